"""Charts from known data: the plotted lines carry the data (checked on the figure before saving) and each file
is a real, non-empty PNG; the terminal chart fits 80 columns; a missing matplotlib is one clear line."""

from __future__ import annotations

import math
import struct
import sys
from pathlib import Path

import pytest

from servotool.errors import UsageError
from servotool.ops.trace_file import Series, TimeTable, read_table
from servotool.report.terminal import terminal_chart

pytest.importorskip("matplotlib")

from servotool.report import tune_report
from servotool.report.charts import MISSING, PNG_SIGNATURE, need_matplotlib, save, table_figure
from servotool.report.tune_facts import gain_rows


def assert_png(path: Path) -> tuple[int, int]:
    """A PNG by its signature and IHDR chunk, bigger than a blank; returns (width, height)."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert width >= 300 and height >= 200 and len(data) > 5000
    return width, height


def lines_of(fig) -> dict[str, tuple[list[float], list[float]]]:
    return {
        ln.get_label(): (list(ln.get_xdata()), list(ln.get_ydata()))
        for ax in fig.axes
        for ln in ax.get_lines()
        if not ln.get_label().startswith("_")
    }


def _table() -> TimeTable:
    t = [i * 0.01 - 0.2 for i in range(100)]
    return TimeTable(
        Path("known.csv"),
        "t_s",
        t,
        [
            Series("Un000", "rpm", [3.0 * i for i in range(100)]),
            Series("Un001", "rpm", [2.0 * i for i in range(100)]),
            Series("Un002", "%", [50.0 - i for i in range(100)]),
        ],
        capture=[1] * 100,
    )


def test_a_table_chart_has_one_panel_per_unit_and_each_column_s_data(tmp_path):
    table = _table()
    fig = table_figure(table)
    assert len(fig.axes) == 2 and [ax.get_ylabel() for ax in fig.axes] == ["rpm", "%"]
    lines = lines_of(fig)
    assert set(lines) == {"Un000 [rpm]", "Un001 [rpm]", "Un002 [%]"}
    assert lines["Un002 [%]"][1] == table.series[2].values and lines["Un000 [rpm]"][0] == table.t
    assert_png(save(fig, tmp_path / "known.png"))


def test_the_terminal_chart_fits_80_columns_with_a_legend_and_names_what_found_no_room():
    chart = terminal_chart(_table(), 80, 30, "known", color=False)
    lines = chart.text.splitlines()
    assert max(len(line) for line in lines) <= 80 and "Un001 [rpm]" in chart.text and "Un002 [%]" in chart.text
    short = terminal_chart(_table(), 80, 10, color=False)
    assert short.left_out == ["Un002 [%]"] and "Un000 [rpm]" in short.text


def test_reading_a_monitor_and_a_tune_csv(tmp_path):
    mon = tmp_path / "mon.csv"
    mon.write_text(
        "timestamp,elapsed_s,Un000 [rpm],5E00h\n2026-01-01T00:00:00.000,0.0,1,3\n2026-01-01T00:00:00.100,0.1,2,3\n"
    )
    table = read_table(mon)
    assert [s.label for s in table.series] == ["Un000 [rpm]", "5E00h"] and table.t == [0.0, 0.1]
    tune = tmp_path / "tune.csv"
    tune.write_text("t_s,speed_rpm,torque_pct,position_rev\n0.0,1.0,2.0,\n0.01,2.0,3.0,0.5\n")
    table = read_table(tune)
    assert [s.label for s in table.series] == ["speed [rpm]", "torque [%]", "position [rev]"]
    assert math.isnan(table.series[2].values[0])
    position = lines_of(table_figure(table))["position [rev]"]
    assert position == ([0.01], [0.5])  # drawn where it was read, no NaN gap
    with pytest.raises(UsageError, match="no column Un999"):
        table.select(["Un999"])
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(UsageError, match="no time column"):
        read_table(tmp_path / "bad.csv")


def test_without_matplotlib_the_message_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(UsageError) as exc:
        need_matplotlib()
    assert str(exc.value) == MISSING and "pip install '.[plot]'" in MISSING


def test_every_tune_chart_shows_the_tune_s_data(tuned, tmp_path):
    profile, res = tuned
    result = res.identified
    trace = result.trace
    motion = lines_of(tune_report.motion_figure(result))
    assert motion["speed"] == (trace.t, trace.speed) and motion["torque"][1] == trace.torque
    travel = [x - trace.position[0] for x in trace.position if x is not None]
    assert motion["travel"][1] == pytest.approx(travel) and max(map(abs, travel)) > 0.2

    est = result.estimate
    fit = lines_of(tune_report.fit_figure(result, profile))
    pct = 100.0 / profile.motor.rated_torque_nm
    wins = est.fitted_windows
    centres = [(w.t0 + w.t1) / 2 for w in wins]
    assert fit["measured, each window's average"] == (
        pytest.approx(centres),
        pytest.approx([w.measured_nm * pct for w in wins]),
    )
    model_x, model_y = fit["model: J·Δω/Δt + friction + load, in the windows fitted"]
    drawn = [(x, y) for x, y in zip(model_x, model_y, strict=True) if not math.isnan(x)]
    assert [x for x, _y in drawn] == pytest.approx(centres)
    assert [y for _x, y in drawn] == pytest.approx([w.model_nm * pct for w in wins])
    # the model is drawn only inside the windows fitted: between runs of windows the line breaks
    assert all(any(w.t0 <= x <= w.t1 for w in wins) for x, _y in drawn) and any(math.isnan(x) for x in model_x)
    resid = [(w.measured_nm - w.model_nm) * pct for w in wins]
    assert fit["measured − model"][1] == pytest.approx(resid)
    # the window residual of the title is what is drawn: small against the torque swing
    assert (sum(r * r for r in resid) / len(resid)) ** 0.5 < 0.25 * (max(trace.torque) - min(trace.torque))

    moves = [m for m in est.moves if m.fitted]
    assert len(moves) >= 4 and {m.direction for m in moves} == {1, -1}
    assert all(abs(m.load_ratio - 3.0) < 3 * m.ratio_std + 0.05 for m in moves)  # the simulated load ratio is 3
    fig = tune_report.moves_figure(result)
    plotted = fig.axes[0].collections
    ys = [list(c.get_offsets()[:, 1]) for c in plotted if len(c.get_offsets()) == len(moves)]
    assert pytest.approx([m.load_ratio for m in moves]) in ys

    step = lines_of(tune_report.step_figure(res.step_before, res.step_after))
    before = next(v for k, v in step.items() if k.startswith("before: overshoot"))
    assert before == ([t * 1000 for t in res.step_before.t_s], list(res.step_before.speed_rpm))
    after = next(v for k, v in step.items() if k.startswith("after: overshoot"))
    assert before[0][0] == after[0][0] == 0.0 and abs(before[1][0]) < 10 and abs(after[1][0]) < 10  # one zero
    assert step[f"after: settled at {res.step_after.settling_ms:.0f} ms"][0][0] == pytest.approx(
        res.step_after.settling_ms
    )
    assert res.step_after.overshoot_pct < res.step_before.overshoot_pct

    rows = gain_rows(res)
    assert [r.code for r in rows] == [c.entry.code for c in res.proposal.gain_changes]


def test_the_report_folder_holds_valid_pngs_and_a_report_that_links_them(tuned, tmp_path):
    profile, res = tuned
    report = tune_report.write_tune_report(tmp_path / "rep", res.identified, profile, res)
    names = [p.name for p in report.files]
    assert names == ["motion.png", "fit.png", "moves.png", "step.png", "gains.png", "report.md"]
    for p in report.files[:-1]:
        assert_png(p)
    md = (tmp_path / "rep" / "report.md").read_text()
    for p in report.files[:-1]:
        assert f"]({p.name})" in md
    assert f"{res.ratio:.2f}" in md and "overshoot" in md and res.proposal.gain_changes[0].entry.code in md
    assert "| move speeds | reached " in md and "| move | direction | peak speed | ratio |" in md


def test_a_report_folder_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(UsageError, match="it is a file"):
        tune_report.check_folder(tmp_path / "f")


def test_each_capture_of_a_repeated_trace_is_its_own_line():
    table = _table()
    table.capture = [1] * 50 + [2] * 50
    lines = lines_of(table_figure(table))
    assert lines["Un002 [%] #1"][1] == table.series[2].values[:50]
    assert lines["Un002 [%] #2"][1] == table.series[2].values[50:]
    assert "Un000 [rpm] #2" in terminal_chart(table, 100, 30, color=False).text


def _result_with(result, **changes):
    """The tune's result with its estimate changed (a made-up move, a refusal)."""
    import dataclasses

    return dataclasses.replace(result, estimate=dataclasses.replace(result.estimate, **changes))


def test_a_move_without_a_ratio_of_its_own_is_marked_not_plotted(tuned):
    """A move that cannot be fitted was plotted at -0.99 (no load is lighter than nothing); it is marked along the
    bottom with why, and the axis is the fitted moves'."""
    from servotool.tuning.fit import MoveEstimate

    _profile, res = tuned
    moves = res.identified.estimate.moves
    lost = MoveEstimate(1, math.nan, math.nan, 3, 40.0, "no load gives it: J 0.01 x the rotor's")
    fig = tune_report.moves_figure(_result_with(res.identified, moves=(*moves, lost)))
    ax = fig.axes[0]
    low, high = ax.get_ylim()
    assert low > 1.0 and high < 5.0  # scaled to the fitted moves around 3, not stretched to -0.99
    [marked] = [c for c in ax.collections if c.get_label().startswith("no ratio of its own (")]
    assert len(moves) + 1 in list(marked.get_offsets()[:, 0])


def test_one_very_uncertain_move_runs_off_the_axis_instead_of_flattening_the_others(tuned):
    import dataclasses

    _profile, res = tuned
    moves = list(res.identified.estimate.moves)
    i = next(i for i, m in enumerate(moves) if m.fitted)
    moves[i] = dataclasses.replace(moves[i], ratio_std=1400.0)
    fig = tune_report.moves_figure(_result_with(res.identified, moves=tuple(moves)))
    ax = fig.axes[0]
    low, high = ax.get_ylim()
    assert high - low < 10
    assert any(t.get_text() == "± 1.4e+03" for t in ax.texts)


def test_a_refused_result_shows_no_ratio(tuned, tmp_path):
    profile, res = tuned
    refused = _result_with(res.identified, ok=False, reason="inertia too uncertain (7.8 % of J_total > 2 %)")
    tune_report.write_tune_report(tmp_path / "rep", refused, profile, None, "identification refused: too uncertain")
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "none: the identification was refused" in md and f"→ {res.ratio:.2f}" not in md
    fig = tune_report.fit_figure(refused, profile)
    assert fig._suptitle.get_text().startswith("REFUSED fit") and "ratio" not in fig._suptitle.get_text()
