"""Plan steps that move the motor: jog, tune inertia (the same code as `servotool jog` and `tune inertia`)."""

from __future__ import annotations

from typing import Any

from servotool.commission.plan import JOG_KEYS, TUNE_KEYS, Step
from servotool.commission.plan_files import FileUse
from servotool.commission.step_type import Outcome, RunContext, StepType, number_in
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import parse_value
from servotool.model.profile import Profile
from servotool.model.quantity import quantity
from servotool.model.roles import motion_route
from servotool.motion.deadman import lines, sentence
from servotool.motion.stop import proven_on_interrupt
from servotool.report.charts import need_matplotlib
from servotool.report.tune_report import write_tune_report
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.planning import MotionPlan, identification_bound
from servotool.tuning.stable_hold import guarded_jogger
from servotool.tuning.tune import TuneRequest, check_request, tune_inertia


class JogStep(StepType):
    """`jog: {speed: RPM, time: S, max_travel: REV}`: a timed JOG with the dead-man."""

    name = "jog"

    def describe(self, step: Step, profile: Profile) -> str:
        arg = step.arg
        if not isinstance(arg, dict) or set(arg) - JOG_KEYS or "speed" not in arg or "time" not in arg:
            raise UsageError("jog needs {speed: RPM, time: S} (optional max_travel)")
        route = motion_route(profile, "jog")  # a JOG trigger or speed reference + servo-on
        speed = number_in(arg["speed"], "jog speed", -100_000, 100_000)
        secs = number_in(arg["time"], "jog time", 0, 600)
        if speed == 0 or secs == 0:
            raise UsageError("jog speed must be non-zero and time 0..600 s")
        parse_value(route.speed_entry, f"{abs(speed):g}")
        if "max_travel" in arg:
            limit = number_in(arg["max_travel"], "jog max_travel", 0, 10_000)
            if abs(speed) / 60 * secs > limit:
                raise UsageError(
                    f"a {secs:g} s JOG at {abs(speed):g} rpm travels about {abs(speed) / 60 * secs:.2f} "
                    f"rev, over its max_travel {limit:g} rev"
                )
        return f"jog {speed:g} rpm for {secs:g} s"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        drive.dead_man_waived = waived(step.arg)
        with proven_on_interrupt(drive):  # an interrupt before the JOG moves ends with the drive read back
            jogger = guarded_jogger(drive)
            plan = jogger.plan(float(step.arg["speed"]), float(step.arg["time"]), step.arg.get("max_travel"))
            if plan.dead_man is not None:  # the bound, then what else bounds the motion (protections, forced inputs)
                first, *more = lines(plan.dead_man)
                ctx.safety(f"unit {drive.unit}: {first}")
                for line in more:
                    ctx.safety(line)
            jogger.run(plan)
        bound = plan.dead_man
        return Outcome(
            plan.describe() + (f"; {sentence(bound)}" if bound is not None else ""),
            {"dead_man": bound.as_json()} if bound is not None else {},
        )


def waived(arg: Any) -> bool:
    """`no_dead_man: true` in a motion step: the plan's author acknowledges a drive without a dead-man."""
    value = (arg or {}).get("no_dead_man", False) if isinstance(arg, dict) else False
    if not isinstance(value, bool):
        raise UsageError("no_dead_man must be true or false")
    return value


def _report_option(arg: Any) -> str | None:
    """The step's `report: DIR` (charts need matplotlib: refused before the plan runs when it is missing)."""
    report = (arg or {}).get("report") if isinstance(arg, dict) else None
    if report is None:
        return None
    if not isinstance(report, str) or not report.strip():
        raise UsageError("tune inertia report must be a folder name")
    need_matplotlib()
    return report


class TuneInertiaStep(StepType):
    """`tune inertia: {rigidity, bandwidth, travel, max_speed, accel_time, direction, repeats, gains, check,
    report}`: what `servotool tune inertia --yes --check` does (host method): the gains are set only with rigidity
    or bandwidth (or `gains: true`: at the drive's own current level), as the command leaves them alone without,
    and are step-checked once written (a failed check writes the previous gains back and fails the step; `check:
    false` leaves the check out); `report: DIR` writes the charts and report.md there (as `--report DIR`)."""

    name = "tune inertia"

    def request(self, arg: Any, profile: Profile) -> TuneRequest:
        """The step's options as a checked request (unset motion options automatic, as in the command)."""
        opts = arg or {}
        if not isinstance(opts, dict) or set(opts) - TUNE_KEYS:
            raise UsageError(f"tune inertia options are {', '.join(sorted(TUNE_KEYS))}")
        direction = opts.get("direction", "both")
        if not isinstance(direction, str):
            raise UsageError("tune inertia direction must be both, forward or reverse")
        repeats = number_in(opts["repeats"], "tune inertia repeats", 1, 20) if "repeats" in opts else None
        if repeats is not None and repeats != int(repeats):
            raise UsageError("tune inertia repeats must be a whole number 1..20")
        rigidity, bandwidth = opts.get("rigidity"), opts.get("bandwidth")
        gains = opts.get("gains", rigidity is not None or bandwidth is not None)
        if not isinstance(gains, bool):
            raise UsageError("tune inertia gains must be true or false")
        check = opts.get("check", True)  # gains written in a plan are step-checked unless the plan says not
        if not isinstance(check, bool):
            raise UsageError("tune inertia check must be true or false")
        if rigidity is not None and (isinstance(rigidity, bool) or not isinstance(rigidity, int)):
            raise UsageError(f"tune inertia rigidity must be a whole number, got {rigidity!r}")
        request = TuneRequest(
            max_speed=number_in(opts["max_speed"], "tune inertia max_speed", 0, 100_000)
            if "max_speed" in opts
            else None,
            accel_time_ms=number_in(opts["accel_time"], "tune inertia accel_time", 20, 5000)
            if "accel_time" in opts
            else None,
            travel_rev=number_in(opts.get("travel", 2.0), "tune inertia travel", 0, 10_000),
            travel_given="travel" in opts,
            direction=direction,
            repeats=None if repeats is None else int(repeats),
            gains=gains,
            verify=gains and check,
            rigidity=rigidity,
            bandwidth_hz=None if bandwidth is None else number_in(bandwidth, "tune inertia bandwidth", 0, 10_000),
        )
        check_request(profile, request, "tune inertia")
        return request

    def describe(self, step: Step, profile: Profile) -> str:
        motion = self.request(step.arg, profile).nominal_motion(profile)
        gains = self.request(step.arg, profile).gains
        report = _report_option(step.arg)
        reported = (
            ""
            if profile.role("inertia_ratio") is not None
            else f"; the ratio is reported, not written ({profile.id} maps no inertia-ratio parameter)"
        )
        check = self.request(step.arg, profile).verify
        return (
            f"tune inertia: {motion.describe()}"
            + ("" if gains else "; gains left as they are")
            + ("; the gains step-checked once written" if check else "; gains NOT step-checked" if gains else "")
            + reported
            + (f"; report to {report}" if report else "")
        )

    def files(self, step: Step, profile: Profile) -> list[FileUse]:
        report = _report_option(step.arg)
        return [FileUse(report, "tune report")] if report else []

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        request = self.request(step.arg, drive.profile)
        drive.dead_man_waived = waived(step.arg)
        report = _report_option(step.arg)
        folder = ctx.path(report, drive.unit) if report else None

        def announce(motion: MotionPlan | None) -> bool:
            if motion is not None:
                ctx.safety(f"unit {drive.unit}: {sentence(identification_bound(drive, motion))}")
            return True

        try:
            with proven_on_interrupt(drive):  # an interrupt before a motion, or between two, ends with a read-back
                res = tune_inertia(drive, request, clock=ctx.clock, approve_motion=announce)
        except IdentificationRefused as exc:
            if folder is not None:
                write_tune_report(folder, exc.result, drive.profile, None, str(exc))
            raise
        if folder is not None:
            write_tune_report(folder, res.identified, drive.profile, res)
        for entry, raw in res.written:
            ctx.wrote(drive, entry, raw)
        proposal = res.proposal
        entry, value = proposal.parameter, proposal.parameter_value
        data: dict[str, Any] = {"ratio": round(res.ratio, 4)}
        if entry is not None:
            data[entry.code] = quantity(value, entry.unit)
        checked = ""
        if request.gains:
            data["gains"] = {c.entry.code: quantity(c.new, c.entry.unit) for c in proposal.gain_changes}
        if res.verified is not None:
            data["step_check"] = res.verified.summary()
            checked = f"; gains step-checked: overshoot {res.verified.overshoot_pct:.0f} %"
        data["persisted"] = res.persisted
        if folder is not None:
            data["report"] = str(folder / "report.md")
        if entry is None:
            return Outcome(
                f"load ratio {res.ratio:.2f} (nothing to write: {drive.profile.id} maps no inertia-ratio parameter)"
                + checked,
                data,
            )
        return Outcome(f"load ratio {res.ratio:.2f} -> {entry.code}={value:g}{checked}", data)
