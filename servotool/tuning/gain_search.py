"""`tune gains`: raise the drive's own rigidity level step by step with a step check at each, as vendors'
one-parameter auto-tuning does; stop at the first level that overshoots, rings or trips, back off, keep a safe level.

Levels are tried only where the computed margins allow them (tuning.control.margins): the search never writes gains the
margin check refuses. Each level's gains are written to RAM where the drive lets us keep them out of EEPROM; the
chosen level is written last by the drive's EEPROM rule (save). When even the first level fails, the gains the
drive had go back and the search fails.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.codec import format_value, raw_to_eng
from servotool.motion.interrupts import held_interrupts
from servotool.ops import eeprom
from servotool.ops.params import write_one
from servotool.tuning import gain_writes, step
from servotool.tuning.control.gains import rigidity_scale
from servotool.tuning.control.margins import Margins
from servotool.tuning.gain_writes import GainChange
from servotool.tuning.preflight import preflight
from servotool.tuning.step import StepResponse

BACK_OFF_LEVELS = 1  # below the last level that passed: a margin for load changes and wear


@dataclass(frozen=True)
class LevelTrial:
    level: int
    speed_gain_hz: float
    margins: Margins
    response: StepResponse | None
    failure: str | None  # None: passed


@dataclass
class GainSearch:
    load_ratio: float
    start_level: int
    own_ratio: float | None = None  # the drive's own ratio parameter (None: it has none)
    trials: list[LevelTrial] = field(default_factory=list)
    chosen: int | None = None
    changes: list[GainChange] = field(default_factory=list)  # the chosen level's writes (old: before the search)
    persisted: bool | None = None
    reason: str = ""  # why the search stopped where it did


class GainSearchFailed(ServoError):
    """Not even the first level passed its step check; the previous gains are back."""

    exit_code = 1

    def __init__(self, message: str, search: GainSearch) -> None:
        super().__init__(message)
        self.search = search


def own_load_ratio(drive: Drive) -> float | None:
    """The drive's own inertia-ratio parameter as J_load/J_motor (identified by tune inertia); None where the
    profile maps none."""
    entry = drive.profile.role("inertia_ratio")
    if entry is None:
        return None
    return drive.profile.load_ratio_from_param(float(raw_to_eng(entry, drive.read_entries([entry])[0].raw)))


def drive_load_ratio(drive: Drive, load_ratio: float | None) -> float:
    """The load ratio to tune for: given, else the drive's inertia-ratio parameter (identified by tune inertia)."""
    if load_ratio is not None:
        if not 0 <= load_ratio <= 1000:
            raise UsageError("--load-ratio must be 0..1000 (J_load/J_motor)")
        return load_ratio
    own = own_load_ratio(drive)
    if own is None:
        raise UsageError(f"{drive.profile.id} keeps no inertia ratio: give --load-ratio (from tune inertia --dry-run)")
    return own


def search_gains(
    drive: Drive,
    *,
    load_ratio: float | None = None,
    start: int | None = None,
    top: int | None = None,
    travel_rev: float = 2.0,
    save: bool | None = None,
    clock: Clock | None = None,
    progress: Callable[[LevelTrial], None] | None = None,
) -> GainSearch:
    """Try levels from `start` (the drive's current level) up to `top` (the highest the margins allow)."""
    clock = clock or RealClock()
    p = drive.profile
    eeprom.check_save_request(p, save)
    step.step_duration_s(travel_rev)
    scale = rigidity_scale(p)
    ratio = drive_load_ratio(drive, load_ratio)
    own = own_load_ratio(drive) if load_ratio is not None else ratio
    motor = p.motor
    assert motor is not None
    jm = motor.rotor_inertia_kgcm2 * 1e-4
    j_total = jm * (1 + ratio)
    # The drive scales its speed gain by the ratio it holds, which --load-ratio does not change: the margins are
    # those of the load given under the drive's own ratio.
    configured = jm * (1 + own) if own is not None and own != ratio else None
    first = scale.check(start) if start is not None else gain_writes.current_level(drive, scale)
    highest = gain_writes.safe_level(p, scale, j_total, scale.check(top) if top is not None else None, configured)
    if highest is None or highest < first:
        held = p.role("inertia_ratio")
        under = (
            f" under the drive's own ratio {own:.2f} ({held.code}), by which it scales its gains: write "
            f"{held.code} = {p.param_from_load_ratio(ratio):g} first, or run tune inertia"
            if configured is not None and held is not None and own is not None
            else ""
        )
        raise UsageError(f"no level from {first} up keeps 45° and 6 dB of margin on load ratio {ratio:.2f}{under}")
    preflight(drive, "host")
    check = step.plan_step(drive, travel_rev)
    search = GainSearch(ratio, first, own_ratio=own)
    original: list[GainChange] = []
    for level in range(first, highest + 1):
        sugg, changes, found = gain_writes.gain_changes(
            drive, ratio, rigidity=level, bandwidth_hz=None, configured_kgm2=configured
        )
        original = original or changes
        try:
            _write(drive, changes, False)
            try:
                response: StepResponse | None = step.step_response(drive, check.speed_rpm, check.duration_s, clock)
                failure = response.failure() if response is not None else None
            except ServoError as exc:
                response, failure = None, str(exc)
        except BaseException as exc:  # Ctrl-C, SIGTERM, a lost line: no level was chosen, the gains go back
            _roll_back(drive, original, save, exc)
            raise
        trial = LevelTrial(level, sugg.speed_loop_gain_hz, found, response, failure)
        search.trials.append(trial)
        if progress is not None:
            progress(trial)
        if failure is not None:
            break
    passed = [t.level for t in search.trials if t.failure is None]
    if not passed:
        _restore(drive, original, save)
        search.reason = f"level {first} failed its step check ({search.trials[0].failure}): previous gains written back"
        raise GainSearchFailed(
            f"level {first} already fails its step check ({search.trials[0].failure}): the "
            "previous gains were written back",
            search,
        )
    failed = any(t.failure is not None for t in search.trials)
    chosen = max(first, passed[-1] - BACK_OFF_LEVELS) if failed else passed[-1]
    _sugg, changes, _m = gain_writes.gain_changes(
        drive, ratio, rigidity=chosen, bandwidth_hz=None, configured_kgm2=configured
    )
    search.chosen = chosen
    last = search.trials[-1]
    search.reason = (
        f"level {last.level} failed ({last.failure}): backed off to {chosen}"
        if failed
        else f"level {chosen} is the highest with 45° and 6 dB of computed margin"
    )
    search.changes = [
        GainChange(c.role, c.entry, o.old, c.new, c.raw, o.old_raw) for c, o in zip(changes, original, strict=True)
    ]
    search.persisted = _write(drive, changes, save)
    return search


def _write(drive: Drive, changes: list[GainChange], save: bool | None) -> bool:
    with eeprom.persistence(drive, save) as outcome:
        for c in changes:
            write_one(drive, c.entry, c.raw)
    return outcome["persisted"]


def _restore(drive: Drive, original: list[GainChange], save: bool | None, raise_held: bool = True) -> None:
    with held_interrupts(raise_held), eeprom.persistence(drive, save):
        for c in original:
            write_one(drive, c.entry, c.old_raw)


def _roll_back(drive: Drive, original: list[GainChange], save: bool | None, exc: BaseException) -> None:
    """The gains before the search back after an interrupt; a note on it says so, or that a level's gains stay."""
    try:
        _restore(drive, original, save, raise_held=False)
    except ServoError as failure:
        exc.add_note(
            f"the search was interrupted and writing the previous gains back failed ({failure}): the gains of the "
            "level being checked stay"
        )
        return
    exc.add_note(
        "the search was interrupted during a step check: the gains before it were written back ("
        + ", ".join(f"{c.entry.code} {format_value(c.entry, c.old_raw)}" for c in original)
        + ")"
    )
