"""Last stage of the fit: the estimate, with the checks' J and notes, and the refusals only the whole result decides
(a non-physical J, a model that does not fit, an uncertainty over the limit)."""

from __future__ import annotations

import math

import numpy as np

from servotool.tuning.fit import quantization
from servotool.tuning.fit.estimate import EstimatorSettings, FittedWindow, InertiaEstimate, MoveEstimate, Partial
from servotool.tuning.fit.regression import Regression
from servotool.tuning.fit.signals import stall_words
from servotool.tuning.fit.subsets import MIN_SUBSET_SHARE
from servotool.tuning.fit.verdict import Verdict


def conclude(r: Partial, fit: Regression, verdict: Verdict, jm: float, cfg: EstimatorSettings) -> InertiaEstimate:
    """The estimate with the model check's J, notes and the refusals that only the whole result can decide."""
    est = dict(zip(fit.names, fit.theta, strict=True))
    err = dict(zip(fit.names, fit.std, strict=True))
    j = float(verdict.j)
    r.j, r.j_std, r.fit_std = j, float(verdict.j_std), float(fit.std[0])
    r.ratio, r.ratio_std = j / jm - 1.0, r.j_std / jm
    r.rate_bound = verdict.rate_bound
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
    stalled = stall_words(verdict.fit.t, verdict.fit.rpm, verdict.fit.own)
    if r.tc < -3 * r.tc_std:
        r.notes.append(negative_coulomb(verdict, stalled))
    r.notes.extend(verdict.notes)
    r.moves = per_move(verdict, jm)
    r.fitted_windows = fitted_windows(verdict)
    if j <= 0:
        return _unresolved_from_the_rotor(r, verdict, jm, cfg) or r.refuse(
            non_physical(verdict, stalled, r.res_rel, cfg.max_rel_residual)
        )
    if r.res_rel > cfg.max_rel_residual and stalled:
        return r.refuse(
            f"model does not fit the data (relative residual {r.res_rel:.2f} > {cfg.max_rel_residual:g}): {stalled} "
            "make the moves uneven; run it again on a quieter host (should it recur there, the mechanics do not "
            "follow the rigid model)"
        )
    if r.res_rel > cfg.max_rel_residual:
        return r.refuse(
            f"model does not fit the data (relative residual {r.res_rel:.2f} > {cfg.max_rel_residual:g}): "
            "backlash, compliance or a torque reading that is not shaft torque"
        )
    if verdict.refuse:
        return r.refuse(verdict.refuse)
    rel = r.j_std / j
    hidden = j < jm and rel > cfg.max_rel_uncertainty
    if hidden and (rotor := _unresolved_from_the_rotor(r, verdict, jm, cfg, steps_only=True)):
        return rotor
    if rel > cfg.max_rel_uncertainty:
        # noise sorting and backlash weigh less in a stronger motion: a longer travel may cure the refusal
        r.shortfall = rel / cfg.max_rel_uncertainty if not verdict.widened or verdict.curable else math.nan
        said = f"inertia too uncertain ({100 * rel:.1f} % of J_total > {100 * cfg.max_rel_uncertainty:g} %)"
        if verdict.widened:
            return r.refuse(f"{said}: {verdict.widened}")
        own = r.fit_std / j
        if own <= cfg.max_rel_uncertainty < rel:
            # a check widened it without words (fit.resonance: a stiffer coupling than the log resolves, not ruled
            # out); the refusal says so, or it reads as a fit that lacked data
            said += (
                f": {100 * own:.1f} % from the fit itself, the rest what the model checks cannot rule out at this "
                "sampling"
            )
        return r.refuse(said, "use stronger accelerations or more moves")
    floor = verdict.floor
    if floor is not None:
        rel = math.hypot(r.j_std / j, floor.rel)
        r.j_std, r.floor_rel = rel * j, floor.rel
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


ROTOR_SIGMAS = 3.0  # a J below the rotor's within this many sigmas of the rotor's own inertia is only uncertain


def _unresolved_from_the_rotor(
    r: Partial, verdict: Verdict, jm: float, cfg: EstimatorSettings, steps_only: bool = False
) -> InertiaEstimate | None:
    """A J below the rotor's own inertia (the least J any load gives) that its uncertainty, with the torque reading's
    floor at that inertia, does not tell from it within ROTOR_SIGMAS: refused as too uncertain there, naming the
    reading's steps where they hide the acceleration, with how far short it fell at the rotor's J (the remedy's
    scale; relative to a J near zero it reads as if no travel could help). None where J lies further below (at or
    below zero: a sign convention). SDC at 20 samples/s, the motor alone with 30 % friction and 40 % gravity: its
    acceleration torque of 0.3 % read in 1 % steps that never moved, and J came out 0 with no residual (blamed on
    the sign convention) or just above it ("80 % uncertain", no travel named). steps_only: None too where the
    reading's steps are not what hides it (a J above zero keeps the fit's own words)."""
    fit = verdict.fit
    found = quantization.floor(fit.t, fit.rpm, fit.pct, jm, fit.torque_step_pct, fit.rated_nm)
    floor_rel = found.rel if found is not None else 0.0
    rel = math.hypot(r.j_std / jm, floor_rel)
    steps_hide = found is not None and floor_rel >= r.j_std / jm
    if jm - r.j > ROTOR_SIGMAS * rel * jm or (steps_only and not steps_hide):
        return None
    # As the fit's own refusal for too uncertain a J: no travel is sought for mechanics a stronger motion leaves as
    # they are (DSX7E 115200, a two-mass load at 10 Hz: "no travel up to 100 rev brings it to 2 %", the mechanics the
    # checks found unsaid).
    curable = not verdict.widened or verdict.curable
    r.shortfall, r.floor_rel = (rel / cfg.max_rel_uncertainty if curable else math.nan), floor_rel
    said = (
        f"inertia too uncertain: J came out {'at or below zero' if r.j <= 0 else 'below the rotor'}, "
        f"{100 * rel:.0f} % uncertain at the rotor's own inertia "
        f"(> {100 * cfg.max_rel_uncertainty:g} %)"
    )
    if steps_hide:
        said += (
            f": the torque reads in {found.step_pct:g} % steps against an acceleration torque of "
            f"{found.signal_pct:.1f} % at the rotor's inertia"
        )
    elif verdict.widened:
        said += f": {verdict.widened}"
    return r.refuse(said, "use stronger accelerations or a faster line") if curable or steps_hide else r.refuse(said)


def non_physical(verdict: Verdict, stalled: str, res_rel: float, max_rel_residual: float) -> str:
    """The refusal for a J at or below zero, naming what the log shows before a sign convention (which turns J
    negative in a log the rigid model fits): the host's stalls, the mechanics the checks found, a model that does not
    fit. IS620P 57600, a two-mass load at 10 Hz (ratio 5, real time) was told to check its sign convention."""
    said = "non-physical result (inertia <= 0)"
    if stalled:
        return f"{said}: {stalled} make the moves uneven; run it again on a quieter host"
    found = [c.words for c in verdict.causes if c.found]
    if found:
        return f"{said}: the load does not follow the rigid model: {'; '.join(found)}"
    if res_rel > max_rel_residual:
        return (
            f"{said}: the model does not fit the data (relative residual {res_rel:.2f} > {max_rel_residual:g}): "
            "backlash, compliance or a torque reading that is not shaft torque"
        )
    return f"{said}: check that torque and speed share a sign convention"


def negative_coulomb(verdict: Verdict, stalled: str) -> str:
    """The note for a Coulomb friction that came out negative, naming what the log shows before a sign convention
    (which would turn J negative too): the host's stalls, or the mechanics the checks fitted, which the rigid model
    the friction is reported from leaves out."""
    if stalled:
        return f"negative Coulomb friction: {stalled} make the moves uneven; the friction figure is not reliable"
    if verdict.fitted:
        causes = "; ".join(c.words for c in verdict.fitted)
        return (
            f"negative Coulomb friction in the rigid model the friction is reported from: it leaves out what the "
            f"fit found ({causes}); the inertia is from the model of it"
        )
    return "negative Coulomb friction: check the torque sign convention against the speed"


MIN_MOVE_WINDOWS = 3  # a move shown on its own needs this many windows (fewer than a subset compared: a picture)
MIN_MOVE_PEAK_SHARE = 0.2  # a run of one speed sign below this share of the fastest is a hold's swing, not a move


def per_move(verdict: Verdict, jm: float) -> tuple[MoveEstimate, ...]:
    """Each move's J, as the subset check takes a subset's (fit.subsets.subset_js): from its own windows of the model
    the checks settled on, the other parameters held at the whole fit's; its uncertainty from the scatter of its own
    windows about that J. A move with too little speed change, or whose J no load can give (below the rotor's own
    inertia by more than 3 of its sigmas, or less certain than J itself), is kept with the reason and no ratio; a
    run far slower than the moves (a position hold swinging back after a move) is no move and left out."""
    fit, resid = verdict.fit, verdict.resid
    dw = fit.x[:, 0]
    total = float(dw @ dw)
    peaks = {
        label: max(
            float(np.max(np.abs(fit.rpm[s : e + 1])))
            for s, e in zip(fit.starts[fit.groups == label], fit.ends[fit.groups == label], strict=True)
        )
        for label in sorted(set(fit.groups[fit.groups >= 0].tolist()))
    }
    fastest = max(peaks.values(), default=0.0)
    out = []
    for label, peak in peaks.items():
        if peak < MIN_MOVE_PEAK_SHARE * fastest:
            continue
        m = fit.groups == label
        idx = np.flatnonzero(m)
        direction = int(np.sign(fit.w[fit.starts[idx[0]]]))
        info, n = float(dw[m] @ dw[m]), idx.size
        if n < MIN_MOVE_WINDOWS or info <= MIN_SUBSET_SHARE * total:
            why = f"too little speed change in its {n} window{'s' if n != 1 else ''} for a J of its own"
            out.append(MoveEstimate(direction, math.nan, math.nan, n, peak, why))
            continue
        shift = float(dw[m] @ resid[m]) / info
        own = resid[m] - shift * dw[m]
        j, j_std = verdict.j + shift, math.sqrt(float(own @ own) / max(1, n - 1) / info)
        ratio, ratio_std = j / jm - 1.0, j_std / jm
        why = ""
        if j <= 0 or ratio + 3.0 * ratio_std < 0:
            why = f"no load gives it: J {j / jm:.2f} x the rotor's (± {ratio_std:.2f}), below the rotor alone"
        elif j_std >= abs(j):
            why = f"its J is less certain than J itself (± {ratio_std:.2f} on a ratio of {ratio:.2f})"
        if why:
            out.append(MoveEstimate(direction, math.nan, math.nan, n, peak, why))
        else:
            out.append(MoveEstimate(direction, ratio, ratio_std, n, peak))
    return tuple(out)


def fitted_windows(verdict: Verdict) -> tuple[FittedWindow, ...]:
    """The windows of the model used, each with its measured and modelled average torque."""
    fit = verdict.fit
    t0, t1 = fit.t[fit.starts], fit.t[fit.ends]
    span = np.where(t1 > t0, t1 - t0, np.nan)
    measured, model = fit.y / span, (fit.y - verdict.resid) / span
    return tuple(
        FittedWindow(float(a), float(b), float(q), float(k))
        for a, b, q, k in zip(t0, t1, measured, model, strict=True)
        if math.isfinite(q) and math.isfinite(k)
    )
