"""Is the rigid model right for this load? The model checks, in the order they run, and their fold.

Mechanics outside the model (backlash, a compliant coupling, gravity that changes with position, cogging, a coarse
torque reading) leave the fit's noise-based uncertainty tight while the answer is wrong. Each check reads the verdict
the checks before it left and returns its own (fit.verdict): it may leave windows out, fit a model of what it found
and take J from it, widen the uncertainty, add its words, or refuse, after which no later check runs. Only J is
corrected: the friction and load torque the estimate reports stay the rigid fit's.

A new check is a module with `check(verdict) -> verdict` and one line in CHECKS.
"""

from __future__ import annotations

from collections.abc import Callable

from servotool.tuning.fit import gaps, load_over_travel, lost_motion, quantization, resonance, subsets
from servotool.tuning.fit.regression import FitData
from servotool.tuning.fit.verdict import Verdict

Check = Callable[[Verdict], Verdict]

CHECKS: tuple[Check, ...] = (
    lost_motion.check,  # first: it changes the windows every later check stands on
    load_over_travel.check,
    resonance.check,  # two-mass, else a spring term
    subsets.check,  # compares the model the checks above settled on across subsets of the windows
    quantization.check,  # a floor on the final J's uncertainty
)


def assess(fit: FitData) -> Verdict:
    """The rigid fit's J, passed through every check in order until one refuses; on a log with a host stall the
    stall is named in place of the mechanics the checks blamed (fit.gaps)."""
    rigid = verdict = Verdict.of(fit)
    for check in CHECKS:
        if verdict.refuse:
            break
        verdict = check(verdict)
    return gaps.name(verdict, rigid)
