"""Last stage of the fit: the estimate, with the checks' J and notes, and the refusals only the whole result decides
(a non-physical J, a model that does not fit, an uncertainty over the limit)."""

from __future__ import annotations

import math

import numpy as np

from servotool.tuning.fit.estimate import EstimatorSettings, InertiaEstimate, MoveEstimate, Partial
from servotool.tuning.fit.regression import Regression
from servotool.tuning.fit.subsets import subset_js
from servotool.tuning.fit.verdict import Verdict


def conclude(r: Partial, fit: Regression, verdict: Verdict, jm: float, cfg: EstimatorSettings) -> InertiaEstimate:
    """The estimate with the model check's J, notes and the refusals that only the whole result can decide."""
    est = dict(zip(fit.names, fit.theta, strict=True))
    err = dict(zip(fit.names, fit.std, strict=True))
    j = float(verdict.j)
    r.j, r.j_std = j, float(verdict.j_std)
    r.ratio, r.ratio_std = j / jm - 1.0, r.j_std / jm
    r.tc, r.tc_std = float(est["Tc"]), float(err["Tc"])
    r.b, r.b_std = float(est.get("B", 0.0)), float(err.get("B", 0.0))
    r.tg, r.tg_std = float(est.get("Tg", 0.0)), float(err.get("Tg", 0.0))
    # The model the checks settled on is what must fit (the windows clear of lost motion, a two-mass load's).
    r.res_rms, y_rms = verdict.residual
    r.res_rel = r.res_rms / y_rms if y_rms > 0 else math.inf
    if not cfg.fit_load_torque:
        r.notes.append(
            "load torque not fitted (one direction only, or told there is none): 'coulomb' is Coulomb + load torque"
        )
    if r.tc < -3 * r.tc_std:
        r.notes.append("negative Coulomb friction: check the torque sign convention against the speed")
    r.notes.extend(verdict.notes)
    r.moves = per_move(verdict, jm)
    if j <= 0:
        return r.refuse("non-physical result (inertia <= 0): check that torque and speed share a sign convention")
    if r.res_rel > cfg.max_rel_residual:
        return r.refuse(
            f"model does not fit the data (relative residual {r.res_rel:.2f} > {cfg.max_rel_residual:g}): "
            "backlash, compliance or a torque reading that is not shaft torque"
        )
    if verdict.refuse:
        return r.refuse(verdict.refuse)
    rel = r.j_std / j
    if rel > cfg.max_rel_uncertainty:
        # noise sorting and backlash weigh less in a stronger motion: a longer travel may cure the refusal
        r.shortfall = rel / cfg.max_rel_uncertainty if not verdict.widened or verdict.curable else math.nan
        said = f"inertia too uncertain ({100 * rel:.1f} % of J_total > {100 * cfg.max_rel_uncertainty:g} %)"
        if verdict.widened:
            return r.refuse(f"{said}: {verdict.widened}")
        return r.refuse(said, "use stronger accelerations or more moves")
    floor = verdict.floor
    if floor is not None:
        rel = math.hypot(r.j_std / j, floor.rel)
        r.j_std = rel * j
        r.ratio_std = r.j_std / j * (1.0 + r.ratio)
        if rel > cfg.max_rel_uncertainty:
            r.shortfall = rel / cfg.max_rel_uncertainty
            return r.refuse(
                f"inertia too uncertain ({100 * rel:.1f} % of J_total > {100 * cfg.max_rel_uncertainty:g} %: the "
                f"torque reads in {floor.step_pct:g} % steps against an acceleration torque of "
                f"{floor.signal_pct:.1f} %)",
                "use stronger accelerations or a faster line",
            )
    return r.result(ok=True, reason="")


MIN_MOVE_WINDOWS = 3  # a move shown on its own needs this many windows (fewer than a subset compared: a picture)


def per_move(verdict: Verdict, jm: float) -> tuple[MoveEstimate, ...]:
    """Each move's J, as the subset check takes a subset's (fit.subsets.subset_js): from its own windows of the model
    the checks settled on, the other parameters held at the whole fit's; moves too small for a J of their own are
    left out."""
    fit = verdict.fit
    out = []
    for move in subset_js(fit.x[:, 0], verdict.j, verdict.j_std, verdict.resid, fit.groups, MIN_MOVE_WINDOWS):
        direction = int(np.sign(fit.w[fit.starts[fit.groups == move.label][0]]))
        out.append(MoveEstimate(direction, move.j / jm - 1.0, move.j_std / jm, move.windows))
    return tuple(out)
