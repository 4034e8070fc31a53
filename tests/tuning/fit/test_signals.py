"""The fit's signals at a slow line: the speed noise, and the windows' ends not picked by their own speed noise.

SDC at 9600 baud samples ~24 times a second: a move is a few samples and its corners a third of them. The logs are
the simulated drive's own (tune inertia, a dry run on virtual time) read without noise; each is fitted again with
fresh noise added to its readings, rounded as the registers round them, so the truth and the noise are known.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning.errors import TravelNeeded
from servotool.tuning.fit import EstimatorSettings
from servotool.tuning.identify import trace_estimate
from servotool.tuning.sampling import Trace
from servotool.tuning.tune import TuneRequest, tune_inertia

SPEED_NOISE_RPM = 5.0
TORQUE_NOISE_PCT = 0.5
REPLICAS = 20
MACHINES = [(20.0, 0.05, 0.2, 3), (10.0, 0.01, -0.2, 4), (37.0, 0.1, 0.0, 5), (5.0, 0.05, 0.4, 6)]


def quiet_sdc_trace(ratio: float, friction: float, gravity: float, seed: int, travel: float | None = None) -> Trace:
    """The trace tune inertia fitted on a simulated SDC at 9600 baud whose readings carry no noise."""
    profile = load_profile("sdc")
    clock = VirtualClock(100.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(
        load_ratio=ratio, friction=friction, viscous=0.0, load_torque=gravity, noise=0.0, seed=seed, brake=1
    )
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    drive = Drive(VirtualLink([sim], clock, 9600), profile, 1)
    drive.dead_man_waived = True  # SDC has no dead-man route; this is about the fit
    request = TuneRequest(dry_run=True, travel_rev=travel or 2.0, travel_given=travel is not None)
    try:
        return tune_inertia(drive, request, clock=clock).identified.trace
    except TravelNeeded as exc:
        return quiet_sdc_trace(ratio, friction, gravity, seed, exc.travel_rev)


def refit_all() -> list[tuple[bool, float, float]]:
    """(accepted, z = error / stated sigma, speed noise estimated) of every refit of MACHINES with fresh noise."""
    profile = load_profile("sdc")
    fit = trace_estimate(profile, None, TORQUE_NOISE_PCT)
    rng = np.random.default_rng(1)
    out = []
    for ratio, friction, gravity, seed in MACHINES:
        trace = quiet_sdc_trace(ratio, friction, gravity, seed)
        assert not trace.speed_t  # SDC reads speed and torque in one request
        for _ in range(REPLICAS):
            speed = np.round(np.asarray(trace.speed) + rng.normal(0.0, SPEED_NOISE_RPM, len(trace.t)))
            torque = np.round(np.asarray(trace.torque) + rng.normal(0.0, TORQUE_NOISE_PCT, len(trace.t)))
            noisy = replace(trace, speed=speed.tolist(), torque=torque.tolist())
            est = fit(noisy, EstimatorSettings(fit_load_torque=True))
            if math.isfinite(est.load_ratio) and est.ratio_std > 0:
                out.append((est.ok, (est.load_ratio - ratio) / est.ratio_std, est.speed_noise_rpm))
    return out


@pytest.fixture(scope="module")
def refits(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[bool, float, float]]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SERVOTOOL_SIM_DIR", str(tmp_path_factory.mktemp("sim")))
        return refit_all()


def test_slow_sampling_fits_are_unbiased_within_their_uncertainty(refits) -> None:
    """Corners that the speed noise hid kept the samples whose noise hid them as window ends, each carrying that
    noise's sign into its window's speed change, and the noise read high over-corrected J by errors-in-variables:
    the errors sat +0.6 to +0.9 sigma high on every one of these loads."""
    z = np.array([zi for _, zi, _ in refits])
    accepted = np.array([zi for ok, zi, _ in refits if ok])
    # 43 of 80 accepted, 38 since a spring term of the other sign within a sigma counts its share too, 34 since J
    # comes from the model with a load term over the travel wherever that term is beyond 2 sigma
    assert z.size >= 0.9 * REPLICAS * len(MACHINES) and accepted.size >= 0.4 * z.size
    # mean z -0.22 until J came from the model with a load term over the travel beyond 2 sigma, -0.41 since: the
    # machine with 40 % gravity and a load of 5 refits at -1.1 (its spread 0.87), where it was -0.47
    assert abs(float(np.mean(z))) < 0.5, float(np.mean(z))
    assert float(np.mean(np.abs(accepted) <= 3.0)) >= 0.95


def test_speed_noise_is_read_without_the_moves_corners(refits) -> None:
    """The median deviation from the neighbours' line counted the moves' corners as noise: 30 % high here."""
    truth = math.hypot(SPEED_NOISE_RPM, 1.0 / math.sqrt(12.0))  # the noise and the 1 rpm register's rounding
    read = np.array([n for _, _, n in refits]) / truth
    assert 0.85 < float(np.median(read)) < 1.15, float(np.median(read))
