"""A lower bound of the inertia's relative uncertainty sigma(J)/J that any host-driven identification can reach on the
bench's machines (bench/inertia_accuracy.py --profiles), from the line's sampling rate, the torque reading's step and
noise, the travel and time budget and the torque limit: what `tune inertia` cannot beat, however it moves or fits.

J is seen only through the acceleration torque J*a against the torque reading's error. With the acceleration known
exactly (an ideal speed or position signal, no loop lag, no friction or load torque to separate: all in the
estimator's favour) every torque sample carries J*a/sigma_T of information, so

    sigma(J)/J >= sigma_T / (tau_a * sqrt(N))

sigma_T: the torque reading's noise and its step (as if the step error were random, q/sqrt(12): it is not, when the
torque stays on one step, so this is optimistic too); tau_a = J*a / rated torque; N = samples in the motion (every
one of them taken while accelerating: no stops, no pilot, no set-up). The acceleration is the strongest that keeps
the travel band within 0.9 x 2 rev and still puts k sampling intervals into each phase of constant acceleration (a
bang-bang speed profile: a = band / T^2 with T = k / rate), capped by the motor's speed and by 60 % of a 300 % torque
limit less friction and gravity. k = 2 is the least with which samples show each phase's slope; today's estimator
gets 5-6 (its windows stay clear of the torque steps at both ends of a phase). k = 1 (phases one sampling interval
long) would need a fit of the commanded profile through a model of the drive's loop, and a loop that follows such
ramps (at the factory inertia ratio a heavy load lags them by 0.1-0.2 s). The rate is what the line carries for
speed and torque back to back (bench line_rate; the identification itself gets about 0.8x of it).

A host does not know the acceleration exactly: it sees the drive's loop follow its ramp only through the speed
readings. --measured adds what their noise (sigma_w: noise x 1000 rpm, as the simulator's) costs when each phase's
acceleration is the slope of its k + 1 speed readings (least squares over a phase that changes the speed by dw):

    sigma(J)/J >= sqrt(sigma_T^2 / (tau_a^2 N) + 12 k^2 / ((k + 1)(k + 2)) * sigma_w^2 / (dw^2 N))

still optimistic (the torque and the speed known to share the phase's timing, no kinks left out, every sample in
a phase), and what the slow rows are short of.

Prints per row the share of the bench's 60 machines whose bound allows sigma <= 2 % (the estimator's acceptance
rule) and <= 1 % (needed for a worst error <= 3 % over some 60 runs), at k = 1, 2, 3, 5 and 7: where that share
is below 95 %, issue 16's acceptance target is out of reach at that line speed for any estimator that needs k
samples per phase.

Run: python bench/inertia_bound.py [--torque-step PCT] [--measured]
"""

from __future__ import annotations

import argparse
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from inertia_accuracy import FACTORY_BAUD, draws, line_rate

from servotool.model.loader import load_profile

BAND_REV = 0.9 * 2.0  # the travel band a motion may use (10 % margin of the 2 rev limit)
MOTION_S = 8.0  # of the 10 s: the rest check and the put-back take the rest
TORQUE_USE = 0.6 * 300.0  # % of rated: identification's share of the simulator's 300 % limit
K_SAMPLES = (1, 2, 3, 5, 7)  # today's automatic ramps: 7 intervals of the rest check, 5-6 of the motion's samples


def bound(
    profile_id: str,
    baud: int,
    machine: tuple[float, float, float, float, float],
    k: int,
    step_pct: float | None = None,
    measured: bool = False,
) -> float:
    """The least sigma(J)/J (fraction) on one machine at k samples per phase of constant acceleration; measured:
    the acceleration known only from the noisy speed readings."""
    p = load_profile(profile_id)
    motor = p.motor
    assert motor is not None
    ratio, coulomb, viscous, gravity, noise = machine
    rate = line_rate(profile_id, baud)
    j = motor.rotor_inertia_kgcm2 * 1e-4 * (1.0 + ratio)
    seg = max(k / rate, BAND_REV / (motor.rated_speed_rpm / 60.0))  # the motor's speed caps v = band / T
    a = 2 * math.pi * BAND_REV / seg**2  # rad/s^2
    w_peak = 2 * math.pi * BAND_REV / seg
    room_pct = TORQUE_USE - 100.0 * (coulomb + abs(gravity) + viscous * w_peak)
    tau_a = min(j * a / motor.rated_torque_nm * 100.0, room_pct)  # % of rated
    step = p.need_role("torque_feedback", "bench").scale if step_pct is None else step_pct
    sigma_t = math.hypot(noise * 100.0, step / math.sqrt(12.0))
    n = rate * MOTION_S
    torque_part = sigma_t / (tau_a * math.sqrt(n))
    if not measured:
        return torque_part
    dw_rpm = w_peak * 30.0 / math.pi * min(1.0, tau_a / (j * a / motor.rated_torque_nm * 100.0))
    speed_part = math.sqrt(12.0 * k * k / ((k + 1) * (k + 2)) / n) * noise * 1000.0 / dw_rpm
    return math.hypot(torque_part, speed_part)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--measured", action="store_true", help="the acceleration known only from the noisy speed")
    ap.add_argument(
        "--torque-step",
        type=float,
        default=None,
        help="the torque reading's step, %% of rated, instead of the profile's (SD25 So-66.B: 0.1?)",
    )
    args = ap.parse_args()
    machines = draws(False)
    print(
        f"{len(machines)} machines (bench/inertia_accuracy.py --profiles); band {BAND_REV} rev, {MOTION_S:g} s of "
        f"samples all at full acceleration, torque up to {TORQUE_USE:g} %"
        + ("; acceleration from the noisy speed" if args.measured else "; acceleration known exactly")
    )
    print(f"{'profile':>7} {'baud':>6} {'line/s':>6} " + " ".join(f"{f'k={k}: <=2% <=1% med%':>22}" for k in K_SAMPLES))
    for pid, factory in FACTORY_BAUD.items():
        for baud in sorted({factory, 19200}, reverse=True):
            cols = []
            for k in K_SAMPLES:
                b = sorted(bound(pid, baud, m, k, args.torque_step, args.measured) for m in machines)
                two = sum(x <= 0.02 for x in b) / len(b)
                one = sum(x <= 0.01 for x in b) / len(b)
                cols.append(f"{two:>11.0%} {one:>4.0%} {100 * b[len(b) // 2]:>5.2f}")
            print(f"{pid:>7} {baud:>6} {line_rate(pid, baud):>6.1f} " + " ".join(cols))


if __name__ == "__main__":
    main()
