"""The inertia fit as one pipeline: validate -> signals -> windows -> regression -> checks -> conclude.

Model (SI units, omega in rad/s, T in N*m):

    J * domega/dt = T - Tc * sign(omega) - B * omega - Tg

integrated over windows of consecutive samples (fit.regression), because differentiating sparse, jittery speed is
hopeless. Each stage refuses in words rather than guess; the model checks (fit.checks) then judge whether the rigid
model is right for this load.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from servotool.tuning.fit.checks import assess
from servotool.tuning.fit.conclude import conclude
from servotool.tuning.fit.estimate import EstimatorSettings, InertiaEstimate, Partial, Refused
from servotool.tuning.fit.regression import fit_data, regress
from servotool.tuning.fit.signals import signals
from servotool.tuning.fit.validate import check_samples, validate_log
from servotool.tuning.fit.windows import choose_windows

KGCM2_TO_KGM2 = 1e-4


def estimate_inertia(
    t_s: np.ndarray | list[float],
    speed_rpm: np.ndarray | list[float],
    torque_pct: np.ndarray | list[float],
    *,
    rated_torque_nm: float,
    rotor_inertia_kgcm2: float,
    torque_limit_pct: float | None = None,
    settings: EstimatorSettings | None = None,
    position_rev: np.ndarray | list[float] | None = None,
    paused: Sequence[tuple[float, float]] = (),
) -> InertiaEstimate:
    """Fit J, Coulomb, viscous and load torque to a logged motion; refuse (ok=False) rather than guess.

    t_s: sample times in s (strictly increasing, any spacing); speed_rpm: motor speed; torque_pct: torque in % of
    rated torque (same sign convention as speed). torque_limit_pct: the drive's active torque limit, used to detect
    saturation (None: not checked). position_rev: the drive's own position readings in motor rev, NaN where none was
    read (None: the position is the speed's integral alone; a host stall then leaves it unknown). paused: (from, to)
    times on t_s's clock where the caller paused its sampling by its own choice (a fit between moves while the drive
    held): a gap there is not named a host stall. Raises ValueError only for malformed input (shapes, non-finite
    values, non-increasing time, non-positive motor data).
    """
    cfg = settings or EstimatorSettings()
    t = np.asarray(t_s, dtype=float)
    rpm = np.asarray(speed_rpm, dtype=float)
    pct = np.asarray(torque_pct, dtype=float)
    validate_log(t, rpm, pct, rated_torque_nm, rotor_inertia_kgcm2, torque_limit_pct)
    pos = None if position_rev is None else np.asarray(position_rev, dtype=float) * 2.0 * np.pi
    if pos is not None and pos.shape != t.shape:
        raise ValueError(f"position must have one entry per sample (got {pos.shape} for {t.shape})")
    jm = rotor_inertia_kgcm2 * KGCM2_TO_KGM2
    r = Partial(n_samples=int(t.size))
    try:
        check_samples(r, pct, torque_limit_pct, cfg)
        sig = signals(t, rpm, pct, rated_torque_nm, cfg, r, pos, paused)
        reg = regress(sig, choose_windows(sig, cfg, r), cfg, r)
    except Refused as exc:
        return r.refuse(str(exc), exc.advice)
    verdict = assess(fit_data(sig, reg, cfg, rated_torque_nm, jm))
    return conclude(r, reg, verdict, jm, cfg)
