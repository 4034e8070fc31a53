"""The inertia fit, pure: a logged motion in, an estimate with its uncertainty and notes out.

validate -> signals -> windows -> regression -> checks -> conclude (fit.pipeline.estimate_inertia runs them in that
order). It imports numpy, the standard library and servotool.model only (tests/test_layers.py holds it), so it runs
on any log, live or saved.
"""

from servotool.tuning.fit.estimate import EstimatorSettings, InertiaEstimate, MoveEstimate
from servotool.tuning.fit.pipeline import estimate_inertia

__all__ = ["EstimatorSettings", "InertiaEstimate", "MoveEstimate", "estimate_inertia"]
