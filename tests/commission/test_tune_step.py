"""A plan's tune step sets gains only when the plan asks for them, as `servotool tune inertia` does (issue 16)."""

from __future__ import annotations

from tests.tuning.realtime_cli import near, run_plan


def test_a_plan_tune_step_without_rigidity_leaves_the_gains_as_they_were(cli, tmp_path):
    codes = ("Pn101", "Pn102", "Pn100", "Pn128", "Pn003")

    def gains() -> dict[str, float]:
        return {p["code"]: p["value"] for p in cli("--port", "sim", "param", "get", *codes, "--json").json()}

    cli("sim", "config", "--load-ratio", "4")
    before = gains()
    plan = tmp_path / "plan.yaml"
    plan.write_text("port: sim\nsteps:\n  - tune inertia: {travel: 12}\n")
    r = run_plan(cli, str(plan), "--yes", "--json")
    assert r.code == 0, r.err
    step = r.json()["steps"][0]
    assert near(step, 4.0) and "gains" not in step
    assert gains() == before  # the ratio was written, the gains left alone
