"""Third stage of the fit: the windows the momentum balance is integrated over.

Disjoint windows of consecutive samples, all outside the zero-speed band with one sign of speed, so that
sign(omega) is constant within a window, and clear of kinks; as short as gives enough speed change against the
speed noise.
"""

from __future__ import annotations

import math

import numpy as np

from servotool.tuning.fit.estimate import EstimatorSettings, Partial, Refused
from servotool.tuning.fit.signals import Signals


def choose_windows(sig: Signals, cfg: EstimatorSettings, r: Partial) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends) of the windows: the shortest that give enough excitation, else the most excited."""
    # Longer windows raise the speed change per window against the (fixed) noise of its two end samples.
    ks = [cfg.window_intervals] if cfg.window_intervals is not None else list(range(1, cfg.max_window_intervals + 1))
    best = (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    for k in ks:
        starts, ends = sign_windows(sig.rpm, sig.band, sig.kink, max(1, k), sig.cut)
        r.n_windows = int(starts.size)
        if r.n_windows < cfg.min_windows:
            break
        dw = sig.w[ends] - sig.w[starts]
        excitation = float(np.sqrt(np.mean(dw**2)) / (math.sqrt(2.0) * sig.noise_w))
        if k == ks[0] or excitation > r.excitation:
            r.excitation, r.window_intervals, best = excitation, k, (starts, ends)
        if excitation >= cfg.min_excitation:
            break
    if r.window_intervals == 0:
        raise Refused(
            f"too few usable windows ({r.n_windows} < {cfg.min_windows}) outside the zero-speed band "
            f"of {sig.band:.3g} rpm and away from torque steps; log a longer motion at higher speed"
        )
    r.n_windows = int(best[0].size)
    return best


def sign_windows(
    rpm: np.ndarray, band: float, kink: np.ndarray, k: int, cut: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint windows of k sampling intervals whose samples all lie outside the zero band with one sign, and
    that span no cut interval (a speed corner: its two samples may end the windows on either side).

    A torque kink sample gets sign 0 too, which cuts the intervals on both sides of it out of every window.
    """
    sign = np.where(rpm >= band, 1, np.where(rpm <= -band, -1, 0))
    sign[kink] = 0
    starts: list[int] = []
    i, n = 0, rpm.size
    cut = np.zeros(max(n - 1, 0), dtype=bool) if cut is None else cut
    while i < n - 1:
        if sign[i] == 0:
            i += 1
            continue
        j = i
        while j + 1 < n and sign[j + 1] == sign[i] and not cut[j]:
            j += 1
        # samples i..j form one run of constant sign
        for s in range(i, j - k + 1, k):
            starts.append(s)
        i = j + 1
    st = np.asarray(starts, dtype=int)
    return st, st + k
