"""Host-driven inertia identification: run the planned moves, sample speed and torque, estimate."""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servotool.clock import Clock, RealClock
from servotool.drive import Drive, coalesce_reads
from servotool.errors import ServoError, UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.profile import Entry
from servotool.model.roles import status_bit
from servotool.motion.jogger import Jogger
from servotool.motion.keepalive import KeepAlive, keepalive_interval_s
from servotool.ops.eeprom import ram_writes
from servotool.ops.params import write_one
from servotool.tuning.estimator import EstimatorSettings, InertiaEstimate, estimate_inertia
from servotool.tuning.planning import PILOT_SHARE, TIME_BUDGET_S, TORQUE_SHARE, MotionPlan
from servotool.tuning.preflight import FEATURE, RestCheck, active_alarm
from servotool.tuning.stable_hold import StableHold, pilot_settings


class IdentificationFailed(ServoError):
    """The motion ran but the result is not trustworthy (or the drive reported failure)."""

    exit_code = 1


class TravelExceeded(IdentificationFailed):
    """The axis moved further than the travel limit; the motion was stopped."""


@dataclass
class Trace:
    t: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    torque: list[float] = field(default_factory=list)
    position: list[float | None] = field(default_factory=list)   # None where position was not read
    # When speed and torque cannot share one request (SD25 reads at most 10 registers), the speed is read a
    # request earlier: its own times, to bring it onto the torque's time base before the fit.
    speed_t: list[float] = field(default_factory=list)

    def aligned_speed(self) -> list[float]:
        """Speed at the torque's sample times (linear between speed reads); the speed itself if read together."""
        if len(self.speed_t) != len(self.t) or len(self.t) < 2:
            return list(self.speed)
        return [float(v) for v in np.interp(self.t, self.speed_t, self.speed)]

    def save(self, path: Path) -> None:
        try:
            with path.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["t_s", "speed_rpm", "torque_pct", "position_rev"])
                for t, v, q, x in zip(self.t, self.speed, self.torque, self.position, strict=True):
                    w.writerow([f"{t:.5f}", f"{v:.2f}", f"{q:.2f}", "" if x is None else f"{x:.4f}"])
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror}") from None


@dataclass
class Result:
    method: str
    old_ratio: float | None     # None: the profile maps no inertia-ratio parameter
    new_ratio: float
    estimate: InertiaEstimate | None
    trace: Trace
    plan: MotionPlan | None
    travel_used_rev: float | None
    time_used_s: float
    samples_per_s: float
    cycles: int = 0


class IdentificationRefused(IdentificationFailed):
    """The motion ran, but the estimate is not trustworthy; the result (with its trace) is attached."""

    def __init__(self, message: str, result: Result) -> None:
        super().__init__(message)
        self.result = result


class Identifier:
    """Runs the identification motion on one drive."""

    def __init__(self, drive: Drive, timing: Clock | None = None, keepalive_s: float | None = None) -> None:
        self.drive = drive
        self.p = drive.profile
        self.timing = timing or RealClock()
        self.keepalive_s = keepalive_s
        self.trace = Trace()    # filled while the motion runs; kept when it fails

    def _eng(self, entry: Entry) -> float:
        return float(raw_to_eng(entry, self.drive.read_entries([entry])[0].raw))

    def current_ratio(self) -> float | None:
        """The drive's configured load ratio; None where the profile maps no inertia-ratio parameter."""
        entry = self.p.role("inertia_ratio")
        return self.p.load_ratio_from_param(self._eng(entry)) if entry is not None else None

    # ----- host method ---------------------------------------------------------------------------------------
    def run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None = None,
                 rest: RestCheck | None = None) -> Result:
        """Pilot cycle, then the planned cycles; fit; raise IdentificationRefused when the fit is refused.

        The motion's own writes (speed, ramp) stay out of EEPROM where the drive has a switch."""
        with ram_writes(self.drive):
            return self._run_host(plan, progress, rest)

    def _run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None,
                  rest: RestCheck | None) -> Result:
        p, d = self.p, self.drive
        beat_s = self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d)
        jogger = Jogger(d, beat_s, FEATURE, self.timing)
        saved = jogger.settings_to_restore()
        hold = StableHold(d, jogger.route.kind, saved)    # a position hold stable for the unknown load
        speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
        pos_e = p.role("position_feedback")
        jog_accel = p.need_role("jog_accel", FEATURE)
        motor = p.motor
        assert motor is not None
        limit_e = p.role("torque_limit_fwd")
        torque_limit = self._eng(limit_e) if limit_e is not None else None
        old_ratio = self.current_ratio()
        noise = rest.speed_noise_rpm if rest is not None else 0.0
        stop_band = max(3.0, 4.0 * noise)
        trace = self.trace = Trace()
        t0 = self.timing.now()
        counts = motor.counts_per_rev
        state = {"pos": None, "pos_t": t0, "lo": 0.0, "hi": 0.0, "pred": 0.0}
        guard: dict[str, float | None] = {"lo": None, "hi": None, "stretch": 1.0}
        # The loop's lag (s): how much further than its ramp the axis coasted after a stop command, per speed. A
        # speed loop configured for a fraction of the real inertia lags its ramps by tens of ms, more with high
        # friction (the integral winds up at breakaway); the stop guard adds the travel of that lag.
        lag = {"s": 0.0}
        pos_every = 0.05   # position costs a request of its own: read it at 20 Hz, predict from speed between

        together = len(coalesce_reads(p, [speed_e, torque_e])) == 1     # one request carries both

        def sample() -> None:
            if together:
                readings = d.read_entries([speed_e, torque_e])
            else:
                readings = d.read_entries([speed_e])
                trace.speed_t.append(self.timing.now() - t0)
                readings += d.read_entries([torque_e])
            now = self.timing.now()
            speed = float(raw_to_eng(speed_e, readings[0].raw))
            if trace.t:   # travel between position reads, from the speed (checked before it is reached)
                state["pred"] += 0.5 * (speed + trace.speed[-1]) / 60.0 * (now - t0 - trace.t[-1])
            trace.t.append(now - t0)
            trace.speed.append(speed)
            trace.torque.append(float(raw_to_eng(torque_e, readings[1].raw)))
            trace.position.append(None)
            if pos_e is not None and (state["pos"] is None or now - state["pos_t"] >= pos_every):
                x = d.read_entries([pos_e])[0].raw / counts
                trace.position[-1] = x
                state["pos"], state["pos_t"], state["pred"] = x, self.timing.now(), x
                state["lo"] = min(state["lo"], x) if len(trace.t) > 1 else x
                state["hi"] = max(state["hi"], x) if len(trace.t) > 1 else x
            # Travel from the position reads, predicted from the speed between them (from the speed alone where
            # the profile has no usable position feedback).
            x = state["pred"]
            state["lo"], state["hi"] = min(state["lo"], x), max(state["hi"], x)
            if state["hi"] - state["lo"] > plan.travel_limit_rev:
                raise TravelExceeded(f"travel limit {plan.travel_limit_rev:g} rev reached: motion stopped; the "
                                     "loop overshoots (inertia ratio far off?): lower --max-speed or raise --travel")
            jogger.keepalive.beat_if_due()

        ramp = plan.ramp_s

        def move(direction: int, speed: float) -> tuple[float, float]:
            """One accelerate-then-stop move; returns (excursion so far in rev, peak |torque| in %)."""
            first = len(trace.t)
            jogger.set_speed(speed)
            jogger.set_ramp(eng_to_raw(jog_accel, ramp * 1000.0 * motor.rated_speed_rpm / speed))
            jogger.command(direction)
            start = self.timing.now()
            while self.timing.now() - start < ramp:   # the drive's ramp reaches the speed in ramp_s
                sample()
                if guard["lo"] is not None:
                    # Stop early where the stopping distance (the ramp's, stretched as the pilot showed) would
                    # carry the axis out of its band: drift (gravity, overshoot) must not add up to the limit.
                    v = abs(trace.speed[-1])
                    stop_rev = guard["stretch"] * v * v * ramp / (2 * speed) / 60.0
                    # ... plus the travel until the stop command can act: the next sample and the write
                    stop_rev += v / 60.0 * 2.0 * (trace.t[-1] - trace.t[-2] if len(trace.t) > 1 else 0.0)
                    stop_rev += v / 60.0 * lag["s"]
                    if (state["pred"] + stop_rev > guard["hi"]) if direction > 0 else \
                            (state["pred"] - stop_rev < guard["lo"]):
                        break
            jogger.command(0)
            stop = self.timing.now()
            at_stop, v_stop = state["pred"], abs(trace.speed[-1]) if trace.speed else 0.0
            while self.timing.now() - stop < 3 * ramp + 0.5:
                sample()
                if self.timing.now() - stop >= ramp and abs(trace.speed[-1]) < stop_band:
                    break
            sample()
            sample()                      # two samples at rest separate this move from the next
            if v_stop > stop_band:
                coast = abs(state["pred"] - at_stop) - v_stop * v_stop * ramp / (2 * speed) / 60.0
                lag["s"] = max(lag["s"], coast / (v_stop / 60.0))
            active = active_alarm(d)
            if active:
                raise IdentificationFailed(f"the drive stopped the identification with alarm {active}")
            peak = max((abs(q) for q in trace.torque[first:]), default=0.0)
            return state["hi"] - state["lo"], peak

        both = len(plan.directions) > 1
        settings = EstimatorSettings(fit_load_torque=both)
        est: InertiaEstimate | None = None
        cycles = 0
        try:
            # Pilot cycle at reduced speed: how far the axis really goes per nominal revolution (a badly matched
            # speed loop overshoots) and how much torque the acceleration takes, before the full test.
            pilot = plan.speed_rpm * PILOT_SHARE
            hold.before_pilot()
            if progress:
                progress(f"pilot move at {pilot:.0f} rpm")
            excursion, peak = 0.0, 0.0
            sample()                      # the axis's real position: the travel band is around it, not around 0
            origin = state["pred"]
            for direction in plan.directions:
                excursion, pk = move(direction, pilot)
                peak = max(peak, pk)
            if hold.active:   # the pilot's rough estimate configures the loop for the main moves
                rate = len(trace.t) / (self.timing.now() - t0)
                hold.after_pilot(self._estimate(pilot_settings(settings), torque_limit, rate))
            nominal = pilot / 60.0 * plan.ramp_s * (1 if both else len(plan.directions))
            limit_rev = plan.travel_limit_rev
            lo = origin - 0.05 * limit_rev if both or plan.directions[0] > 0 else origin - 0.9 * limit_rev
            guard.update(lo=lo, hi=lo + 0.9 * limit_rev, stretch=max(1.0, excursion / nominal))
            # Excursion and torque grow in proportion to the speed at a fixed ramp time.
            speed = plan.speed_rpm
            stretch = float(guard["stretch"] or 1.0)
            if stretch > 1.5:
                # The loop cannot follow the ramps (far-off inertia ratio: an under-damped loop): slower ramps at
                # a lower speed (the same travel) keep its swing inside the travel band.
                factor = min(2.0, stretch / 1.5, 0.5 / ramp)
                ramp, speed = ramp * factor, speed / factor
                guard["stretch"] = stretch / factor
            if excursion > 0:
                room = 0.85 * plan.travel_limit_rev - (excursion if not both else 0.0)
                speed = min(speed, pilot * plan.ramp_s / ramp * room / (excursion * (plan.repeats if not both else 1)))
            if torque_limit is not None and peak > 0:
                speed = min(speed, pilot * TORQUE_SHARE * torque_limit / peak)
            cycle_s = (self.timing.now() - t0) * 1.1
            for rep in range(plan.repeats):
                if plan.adaptive and rep >= 2:
                    if self.timing.now() - t0 + cycle_s > TIME_BUDGET_S:
                        break
                    est = self._estimate(settings, torque_limit, rate=len(trace.t) / (self.timing.now() - t0))
                    if est.ok and est.j_std_kgm2 <= 0.5 * settings.max_rel_uncertainty * est.j_total_kgm2:
                        break
                for direction in plan.directions:
                    if progress:
                        progress(f"move {rep + 1}/{plan.repeats} {'forward' if direction > 0 else 'reverse'} "
                                 f"at {speed:.0f} rpm")
                    move(direction, speed)
                cycles += 1
        except BaseException:
            jogger.stop_quietly()
            raise
        finally:
            jogger.leave_and_restore(saved)
        elapsed = self.timing.now() - t0
        rate = (len(trace.t) - 1) / elapsed if elapsed > 0 else 0.0
        est = self._estimate(settings, torque_limit, rate)
        result = Result("host", old_ratio, est.load_ratio, est, trace, plan, state["hi"] - state["lo"], elapsed,
                        rate, cycles)
        if not est.ok:
            raise IdentificationRefused(f"identification refused: {est.reason}", result)
        return result

    def _estimate(self, settings: EstimatorSettings, torque_limit: float | None, rate: float) -> InertiaEstimate:
        motor = self.p.motor
        assert motor is not None
        # Fast links give many samples per ramp: allow windows long enough to span ~1/5 s.
        cfg = replace(settings, max_window_intervals=max(6, int(rate / 5)))
        return estimate_inertia(self.trace.t, self.trace.aligned_speed(), self.trace.torque,
                                rated_torque_nm=motor.rated_torque_nm, rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
                                torque_limit_pct=torque_limit, settings=cfg)

    # ----- drive method --------------------------------------------------------------------------------------
    def run_drive(self, timeout_s: float = 30.0, keep: bool = True) -> Result:
        """Trigger the drive's own identification, wait for it, read the inertia ratio it stored.

        The drive stores its result itself; keep=False (dry run) puts the previous value back afterwards.
        """
        p, d = self.p, self.drive
        ratio_e = p.need_role("inertia_ratio", FEATURE)
        old_raw = d.read_entries([ratio_e])[0].raw
        old = p.load_ratio_from_param(float(raw_to_eng(ratio_e, old_raw)))
        keepalive = KeepAlive(d, self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d),
                              self.timing)
        t0 = self.timing.now()
        d.trigger("inertia_id", FEATURE)
        status = p.role("servo_status")
        ident_bit = status_bit(status, "identifying") if status is not None else None
        try:
            while self.timing.now() - t0 < timeout_s:
                self.timing.sleep(min(0.1, keepalive.interval_s))
                keepalive.beat()
                if status is None or ident_bit is None:
                    continue
                if not d.read_entries([status])[0].raw >> ident_bit & 1:
                    break
            else:
                raise IdentificationFailed(f"the drive's identification did not finish within {timeout_s:g} s")
        except BaseException:
            try:
                d.trigger("inertia_id", FEATURE, 0)
            except ServoError:
                pass  # the drive's watchdog stops it
            raise
        active = active_alarm(d)
        if active:
            raise IdentificationFailed(f"the drive stopped its identification with alarm {active}")
        new_raw = d.read_entries([ratio_e])[0].raw
        new = p.load_ratio_from_param(float(raw_to_eng(ratio_e, new_raw)))
        if not keep and new_raw != old_raw:
            write_one(d, ratio_e, old_raw)
        return Result("drive", old, new, None, Trace(), None, None, self.timing.now() - t0, 0.0)
