"""JSON numbers as the entries hold them: integers where the scale is 1, rounded to the resolution, measured figures
to the digits they carry (issue 17); one way of giving units, `unit` beside each value ({"value": .., "unit": ..},
issue 33), never a `units` map or a unit in a key's name; encoded values as numbers with their `text`."""

from __future__ import annotations

PLAN = """\
port: sim
profile: dsx7e
steps:
  - expect: {Un000: {value: 0, tol: 50}, Pn101: 18.0}
"""


def _floats(value):
    if isinstance(value, float):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _floats(v)
    elif isinstance(value, list):
        for v in value:
            yield from _floats(v)


def test_tune_json_gives_entry_values_and_rounded_figures(cli):
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--json", "--rigidity", "13", "--travel", "12")
    assert r.code == 0, r.err
    data = r.json()
    assert isinstance(data["parameter_value"]["value"], int)  # Pn004 in %, not 300.0
    assert data["parameter_value"]["unit"] == "%" and "100 %" in data["parameter_value"]["value_unverified"]
    assert data["coulomb"]["unit"] == "N·m" and data["coulomb"]["std"] > 0 and data["bandwidth"]["unit"] == "Hz"
    assert data["step_after"]["overshoot"]["unit"] == "%" and data["dead_man"]["stop_within"]["unit"] == "rev"
    rigidity = next(g for g in data["gains"] if g["code"] == "Pn003")
    assert isinstance(rigidity["old"], int) and rigidity["new"] == 13
    assert all(len(repr(abs(f)).replace(".", "").lstrip("0")) <= 8 for f in _floats(data)), data


def test_a_plan_reports_expected_values_as_numbers_with_units(cli, tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text(PLAN)
    r = cli("run", str(plan), "--yes", "--json")
    assert r.code == 0, r.err
    [step] = r.json()["steps"]
    assert isinstance(step["values"]["Un000"]["value"], int) and step["values"]["Pn101"]["value"] == 18.0
    assert {c: v["unit"] for c, v in step["values"].items()} == {"Un000": "rpm", "Pn101": "Hz"}
    assert "units" not in step and "meanings" not in step


def test_a_plan_reports_an_enum_value_with_its_meaning(cli, tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text("port: sim\nprofile: sdc\nsteps:\n  - set: {PN4: jog}\n  - expect: {PN4: jog}\n")
    r = cli("run", str(plan), "--yes", "--json")
    assert r.code == 0, r.err
    assert r.json()["steps"][1]["values"] == {"PN4": {"value": 3, "unit": "", "meaning": "jog"}}
