"""Sampling gaps: where the log has a gap between samples, while the axis moved, far longer than its usual interval
(a host that stalled: a busy machine; a line that paused), the moves around it are uneven (one ran on, the next was
cut short) and the model checks read that as mechanics: J differing between weak and strong accelerations or along
the travel (backlash?), a spring term (a resonance?). The data cannot tell those apart from the gaps, so the words
name the gaps instead, and a model of mechanics fitted on such a log is not trusted over the rigid fit: what it would
change counts as uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import replace

from servotool.tuning.fit.signals import stall_words
from servotool.tuning.fit.verdict import Cause, Verdict


def name(v: Verdict, rigid: Verdict) -> Verdict:
    """The verdict with the gaps named in place of the mechanics the checks blamed, on a log with a stall; `rigid`:
    the rigid fit's, whose J stands where a model of mechanics was fitted (its change counted as uncertainty). An
    accepted result on such a log says so in its notes, whatever the checks found."""
    fit = v.fit
    said = stall_words(fit.t, fit.rpm, fit.own)
    if not said:
        return v
    uneven = f"{said} make the moves uneven"
    if v.refuse:
        return replace(
            v,
            refuse=f"{uneven}: parts of the log disagree beyond what this can tell apart; run it again on a quieter "
            "host",
        )
    if v.fitted:
        j_std = math.hypot(max(v.j_std, rigid.j_std), v.j - rigid.j)
        cause = Cause(f"{uneven}: J uncertain by what a model of mechanics would change", curable=False)
        note = f"{uneven}: J taken from the rigid model, its uncertainty widened by what a model of mechanics changes"
        return replace(
            v,
            fit=rigid.fit,
            x=rigid.x,
            j=rigid.j,
            j_std=j_std,
            resid=rigid.resid,
            fitted=(),
            widening=cause,
            remarks=(*v.remarks, note),
        )
    if v.widening:
        cause = Cause(f"{uneven}: parts of the log disagree", curable=False)
        kept = tuple(r for r in v.remarks if not r.startswith("off-model:"))  # the mechanics a check blamed
        return replace(v, widening=cause, remarks=(*kept, f"{uneven}: its uncertainty widened"))
    return replace(v, remarks=(*v.remarks, f"{said}: the windows the fit stands on leave them out"))
