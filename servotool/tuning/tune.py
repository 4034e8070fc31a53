"""`tune inertia` as one use case: identify the load inertia, then write the ratio and the gains by the drive's
EEPROM rule.

The CLI, commissioning plans and the accuracy bench all run `tune_inertia`; they differ only in how they ask
(the approve_* callbacks) and how they show the facts it returns.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.codec import format_value
from servotool.model.profile import Entry, Profile
from servotool.motion.interrupts import held_interrupts
from servotool.ops import eeprom
from servotool.ops.params import write_one
from servotool.tuning import gain_writes, identify, planning, preflight, step
from servotool.tuning.budget import Needs
from servotool.tuning.control.gains import GainSuggestion, rigidity_scale, suggest_gains
from servotool.tuning.control.margins import Margins
from servotool.tuning.errors import IdentificationFailed, TravelNeeded, TuneDeclined
from servotool.tuning.gain_writes import GainChange
from servotool.tuning.planning import MotionPlan
from servotool.tuning.preflight import RestCheck
from servotool.tuning.step import StepResponse


@dataclass(frozen=True)
class TuneRequest:
    """What to identify and what to write. Unset motion options are automatic, as `servotool tune inertia`'s."""

    method: str = "host"  # host: servotool moves and fits; drive: the drive's own identification
    max_speed: float | None = None  # rpm; None: from the travel
    accel_time_ms: float | None = None  # None: ramps from the link's sampling rate
    travel_rev: float = 2.0
    travel_given: bool = False  # the user gave (or chose) the travel: the pilot does not stop to name another
    direction: str = "both"
    repeats: int | None = None  # None: repeat until the estimate is precise enough
    gains: bool = False  # set matching gains (at rigidity/bandwidth, else the drive's rigidity)
    rigidity: int | None = None
    bandwidth_hz: float | None = None
    save: bool | None = None  # EEPROM: None as the drive is set, True store, False keep out
    dry_run: bool = False  # identify and report; write nothing
    step_check: bool = False  # a speed step before and after (the after one only once written)
    verify: bool = False  # a step check after gains are written; failed: the old gains go back
    force: bool = False  # write gains even with too little phase/gain margin
    trace_path: Path | None = None  # the sampled trace, also when the identification fails

    def nominal_motion(self, profile: Profile) -> MotionPlan:
        """The host motion before the link's sampling rate is known (raises what is wrong with the options)."""
        return planning.plan_motion(
            profile,
            max_speed=self.max_speed,
            accel_time_ms=self.accel_time_ms,
            travel_rev=self.travel_rev,
            direction=self.direction,
            repeats=self.repeats,
        )

    def host_motion(self, drive: Drive, clock: Clock) -> tuple[MotionPlan, RestCheck]:
        """The host motion for the sampling rate measured while checking the axis at rest."""
        return planning.plan_host_motion(
            drive,
            clock,
            max_speed=self.max_speed,
            accel_time_ms=self.accel_time_ms,
            travel_rev=self.travel_rev,
            direction=self.direction,
            repeats=self.repeats,
        )


def check_request(profile: Profile, request: TuneRequest, feature: str | None = None) -> MotionPlan | None:
    """Everything that can be checked without the drive; returns the host motion as planned before the link's
    sampling rate is known (None for the drive method). feature names the caller in messages (default: the
    command's)."""
    if request.method not in ("host", "drive"):
        raise UsageError("--method must be host or drive")
    eeprom.check_save_request(profile, request.save)
    if request.step_check or request.verify:
        step.step_duration_s(request.travel_rev)
    motion = request.nominal_motion(profile) if request.method == "host" else None
    preflight.check_profile(profile, request.method, feature)
    if request.gains and (request.rigidity is not None or request.bandwidth_hz is not None):
        rotor = profile.motor.rotor_inertia_kgcm2 if profile.motor is not None else 1.0
        try:  # the rules the gains will be computed with, on a nominal load
            suggest_gains(
                rotor_inertia_kgcm2=rotor,
                scale=rigidity_scale(profile),
                load_ratio=1.0,
                rigidity=request.rigidity,
                bandwidth_hz=request.bandwidth_hz,
            )
        except ValueError as exc:
            raise UsageError(f"{feature}: {exc}" if feature else str(exc)) from None
    return motion


@dataclass(frozen=True)
class Proposal:
    """What the identification found and what would be written, before anything is."""

    identified: identify.Result
    parameter: Entry | None  # None: the profile maps no inertia-ratio parameter (reported only)
    parameter_raw: int | None
    suggestion: GainSuggestion | None
    gain_changes: list[GainChange]
    margins: Margins | None = None  # of the suggested gains on the identified inertia
    profile: Profile | None = None

    @property
    def ratio(self) -> float:
        return self.identified.new_ratio

    @property
    def parameter_value(self) -> float | None:
        """The ratio parameter's new value in its unit."""
        return (
            None if self.parameter is None or self.parameter_raw is None else self.parameter_raw * self.parameter.scale
        )

    @property
    def writes_ratio(self) -> bool:
        """The host method writes the ratio parameter (the drive method's drive stores its own)."""
        return self.identified.method == "host" and self.parameter is not None


@dataclass(frozen=True)
class TuneResult:
    """The facts of one `tune inertia`."""

    proposal: Proposal
    ratio_stored: bool  # the drive holds the new ratio (written, or stored by the drive itself)
    gains_written: bool
    persisted: bool | None  # None: nothing written; else whether the writes survive a power cycle
    seconds: float  # the whole run: checks, rest check, identification, writes
    step_before: StepResponse | None = None
    step_after: StepResponse | None = None
    written: list[tuple[Entry, int]] = field(default_factory=list)  # (entry, raw) in the order written
    verified: StepResponse | None = None  # the step check after the gains were written (request.verify)

    @property
    def identified(self) -> identify.Result:
        return self.proposal.identified

    @property
    def ratio(self) -> float:
        return self.proposal.ratio


class GainsRolledBack(ServoError):
    """The step check after writing the gains failed; the previous gains were written back. `reason` is why the
    check failed, `facts` the rollback as a report carries it."""

    exit_code = 1

    def __init__(self, message: str, response: StepResponse | None, reason: str = "") -> None:
        super().__init__(message)
        self.response, self.reason = response, reason
        self.kept: list[str] = []  # codes written before the gains that stay (the inertia ratio)
        self.ratio: float | None = None  # the identified ratio those gains were for

    @property
    def facts(self) -> dict[str, object]:
        return {
            "rolled_back": True,
            "reason": self.reason or str(self),
            "kept": self.kept,
            "step_check": self.response.summary() if self.response is not None else None,
        }


def tune_inertia(
    drive: Drive,
    request: TuneRequest,
    *,
    clock: Clock | None = None,
    progress: Callable[[str], None] | None = None,
    approve_motion: Callable[[MotionPlan | None], bool] | None = None,
    on_proposal: Callable[[Proposal], None] | None = None,
    approve_write: Callable[[Proposal], bool] | None = None,
    choose_travel: Callable[[Needs], float | None] | None = None,
) -> TuneResult:
    """Check, identify, then write the ratio and (if asked) the gains through the drive's EEPROM rule.

    choose_travel is asked, once, where the line needs more travel than the request allows (MotionPlan.needs): a
    travel to use instead, or None to keep it (the pilot then shows whether the load needs more: TravelNeeded). Where
    the travel allowed serves no load at all, TravelNeeded is raised before anything moves. approve_motion sees the
    host motion (None: the drive's own) before anything moves; False raises TuneDeclined. on_proposal sees what was
    identified and would be written, always; approve_write is asked only where something would be written (never on
    a dry run): False writes nothing. Unset: approved.
    """
    clock = clock or RealClock()
    t0 = clock.now()
    check_request(drive.profile, request)
    preflight.preflight(drive, request.method)
    ident = identify.Identifier(drive, clock)
    motion, rest = None, None
    if request.method == "host":
        motion, rest = request.host_motion(drive, clock)
        motion, request = _enough_travel(drive, request, motion, rest, choose_travel)
        motion = replace(motion, travel_given=request.travel_given)
    step_plan = step.plan_step(drive, request.travel_rev) if request.step_check else None  # the travel chosen
    if approve_motion is not None and not approve_motion(motion):
        raise TuneDeclined("nothing moved")
    before = _step(drive, step_plan, clock, load_unknown=True)
    try:
        result = (
            ident.run_host(motion, progress=progress, rest=rest)
            if motion is not None
            else ident.run_drive(keep=not request.dry_run)
        )
    except ServoError:  # refused, tripped, travel exceeded, link lost: keep what was measured
        if request.trace_path is not None:
            ident.trace.save(request.trace_path)
        raise
    if request.trace_path is not None:
        result.trace.save(request.trace_path)
    if result.method == "drive" and not request.dry_run:
        check_drive_result(drive, result, request, clock)
    proposal = propose(drive, result, request)
    if on_proposal is not None:
        on_proposal(proposal)
    approved = (
        not request.dry_run
        and (proposal.writes_ratio or bool(proposal.gain_changes))
        and (approve_write is None or approve_write(proposal))
    )
    written, persisted = _write(drive, proposal, approved, request.save)
    # The host method stores the ratio by writing it; the drive method's drive stored its own (kept unless dry run).
    stored = (proposal.writes_ratio and written != []) if request.method == "host" else not request.dry_run
    try:
        verified = (
            verify_gains(drive, proposal.gain_changes, request, clock)
            if request.verify and approved and proposal.gain_changes
            else None
        )
    except GainsRolledBack as exc:
        gains = {c.entry.code for c in proposal.gain_changes}
        exc.kept = [entry.code for entry, _raw in written if entry.code not in gains]
        exc.ratio = proposal.ratio
        raise
    changed = stored or bool(written)  # SDC stores no ratio: its gains changed all the same
    try:
        after = verified or (_step(drive, step_plan, clock) if before is not None and changed else None)
    except BaseException as exc:  # the check only measures: what was written stays, and the user is told
        if written:
            exc.add_note(f"the values written before the step check stay: {_written_words(written)}")
        raise
    return TuneResult(
        proposal,
        stored,
        approved and bool(proposal.gain_changes),
        persisted,
        clock.now() - t0,
        before,
        after,
        written,
        verified,
    )


def _enough_travel(
    drive: Drive,
    request: TuneRequest,
    motion: MotionPlan,
    rest: RestCheck,
    choose_travel: Callable[[Needs], float | None] | None,
) -> tuple[MotionPlan, TuneRequest]:
    """The motion (and request) with the travel chosen where the line needs more than was allowed; TravelNeeded
    before anything moves where the travel allowed serves no load."""
    needs = motion.needs
    if needs is None or needs.enough:
        return motion, request
    chosen = choose_travel(needs) if choose_travel is not None else None
    if chosen is not None and chosen > request.travel_rev:
        request = replace(request, travel_rev=chosen, travel_given=True)
        plan = planning.plan_motion(
            drive.profile,
            max_speed=request.max_speed,
            accel_time_ms=request.accel_time_ms,
            travel_rev=chosen,
            direction=request.direction,
            repeats=request.repeats,
            samples_per_s=rest.samples_per_s,
        )
        motion = planning.with_needs(planning.fit_run_on(drive, plan), drive, rest)
        needs = motion.needs
        assert needs is not None
    if needs.from_ratio is None:
        light = needs.named
        raise TravelNeeded(
            f"nothing moved: {needs.words()}"
            + (f": where the axis has room, --travel {light.travel_rev:g}" if light is not None else ""),
            light.travel_rev if light is not None else math.nan,
            light.time_s if light is not None else math.nan,
            moved=False,
        )
    return motion, request


def verify_gains(drive: Drive, changes: list[GainChange], request: TuneRequest, clock: Clock) -> StepResponse:
    """The step check after the gains were written; on no settling, overshoot over the limit or an alarm the
    previous gains go back (by the same EEPROM rule) and GainsRolledBack is raised."""
    response: StepResponse | None = None
    try:
        check = step.plan_step(drive, request.travel_rev)
        response = step.step_response(drive, check.speed_rpm, check.duration_s, clock)
        fault = response.failure()
    except ServoError as exc:
        fault = str(exc)
    except BaseException as exc:  # Ctrl-C, SIGTERM: the check did not pass, so the gains it checks do not stay
        _roll_back(drive, changes, request.save, exc, "the step check after writing the gains was interrupted")
        raise
    if fault is None:
        assert response is not None
        return response
    _roll_back(drive, changes, request.save)
    raise GainsRolledBack(
        f"step check after writing the gains failed ({fault}): the previous gains were written back", response, fault
    )


def _roll_back(
    drive: Drive, changes: list[GainChange], save: bool | None, exc: BaseException | None = None, why: str = ""
) -> None:
    """The previous gains written back (by the same EEPROM rule) with interrupts held; with `exc` (the interrupt or
    failure that ended the check), a note on it says what was done, or that the new gains stay."""
    try:
        with held_interrupts(raise_held=exc is None), eeprom.persistence(drive, save):
            for c in changes:
                write_one(drive, c.entry, c.old_raw)
    except ServoError as failure:
        if exc is None:
            raise
        exc.add_note(
            f"{why}: writing the previous gains back failed ({failure}); the new gains stay: "
            + _written_words([(c.entry, c.raw) for c in changes])
        )
        return
    if exc is not None:
        exc.add_note(
            f"{why}: the previous gains were written back ("
            + ", ".join(f"{c.entry.code} {format_value(c.entry, c.old_raw)}" for c in changes)
            + ")"
        )


def _written_words(written: list[tuple[Entry, int]]) -> str:
    return ", ".join(f"{e.code} = {format_value(e, raw)}" for e, raw in written)


def check_drive_result(drive: Drive, result: identify.Result, request: TuneRequest, clock: Clock) -> None:
    """A drive-side result is checked before it is kept: the host method measures the same load, and also fits the
    friction the drive's own method may mistake for inertia; a result outside the host's 3 sigma (plus 5 % of
    J_total) is put back to the previous value and refused."""
    motion, rest = request.host_motion(drive, clock)
    host = identify.Identifier(drive, clock).run_host(motion, rest=rest)
    est = host.estimate
    assert est is not None
    tolerance = 3 * est.ratio_std + 0.05 * (1 + host.new_ratio)
    if abs(result.new_ratio - host.new_ratio) <= tolerance:
        return
    if result.old_ratio is not None:
        entry, raw = gain_writes.ratio_raw(drive, result.old_ratio)
        with eeprom.persistence(drive, request.save):
            write_one(drive, entry, raw)
    raise IdentificationFailed(
        f"the drive's identification gave load ratio {result.new_ratio:.2f}, implausible against the host "
        f"measurement {host.new_ratio:.2f} ± {est.ratio_std:.2f} (friction {est.coulomb_nm:.3g} N·m): the previous "
        f"ratio {result.old_ratio:.2f} was put back; use --method host"
    )


def propose(drive: Drive, result: identify.Result, request: TuneRequest) -> Proposal:
    """The ratio parameter value (where the profile maps one; SDC does not) and the gains for the result."""
    std = result.estimate.ratio_std if result.estimate is not None else 0.0
    entry, raw = (
        gain_writes.ratio_raw(drive, result.new_ratio, std) if drive.profile.role("inertia_ratio") else (None, None)
    )
    if not request.gains:
        return Proposal(result, entry, raw, None, [], None, drive.profile)
    sugg, changes, found = gain_writes.gain_changes(
        drive, result.new_ratio, rigidity=request.rigidity, bandwidth_hz=request.bandwidth_hz, force=request.force
    )
    return Proposal(result, entry, raw, sugg, changes, found, drive.profile)


def _write(
    drive: Drive, proposal: Proposal, approved: bool, save: bool | None
) -> tuple[list[tuple[Entry, int]], bool | None]:
    """The approved writes, inside the drive's EEPROM rule: (written, persisted or None when nothing was)."""
    writes = [(c.entry, c.raw) for c in proposal.gain_changes]
    if proposal.writes_ratio and proposal.parameter is not None and proposal.parameter_raw is not None:
        writes.insert(0, (proposal.parameter, proposal.parameter_raw))
    if not approved or not writes:
        return [], None
    with eeprom.persistence(drive, save) as outcome:
        for entry, raw in writes:
            write_one(drive, entry, raw)
    return writes, outcome["persisted"]


def _step(drive: Drive, plan: step.StepPlan | None, clock: Clock, load_unknown: bool = False) -> StepResponse | None:
    if plan is None:
        return None
    return step.step_response(drive, plan.speed_rpm, plan.duration_s, clock, load_unknown)
