"""Run the real CLI with a Ctrl-C delivered at a named point of a motion command, not at a moment that timing picks:
SIGINT is raised in the process itself (signal.raise_signal, so servotool's own handler takes it) the first time the
point is reached. The points lie where a random Ctrl-C (bench/ctrl_c_storm.py) lands only now and then:

  bound        just after the dead-man bound (or NO DEAD-MAN) line is printed: the plan and protection lines, the
               pre-motion reads and the step check's plan are still to come
  step-check   as a step check starts, before it reads or writes anything (tune gains: the level's gains written)
  snapshot     as a motion's snapshot starts (its settings read and journaled, nothing moved yet)
  protections  just after the drive's own protections for a motion are written, before it moves

Run: python bench/interrupt_at.py POINT [servotool options and command ...]
Exit status and output are servotool's.
"""

from __future__ import annotations

import functools
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

POINTS = ("bound", "step-check", "snapshot", "protections")


def _once(fire: Callable[..., bool], before: bool) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Wrap a function so that SIGINT is raised before (or after) its first call for which fire(*args) holds."""
    done = [False]

    def wrap(function: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(function)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            now = not done[0] and fire(*args)
            if now and before:
                done[0] = True
                signal.raise_signal(signal.SIGINT)
            result = function(*args, **kwargs)
            if now and not before:
                done[0] = True
                signal.raise_signal(signal.SIGINT)
            return result

        return wrapper

    return wrap


def arm(point: str) -> None:
    """Patch the point's function in the modules that call it."""
    if point == "bound":
        import servotool.cli.jog as jog
        import servotool.cli.tune as tune

        def states_bound(text: str) -> bool:
            return "stops within" in text or "NO DEAD-MAN" in text

        for module in (jog, tune):
            module.safety = _once(states_bound, before=False)(module.safety)  # type: ignore[attr-defined]
    elif point == "step-check":
        import servotool.tuning.step as step

        step.step_response = _once(lambda *_: True, before=True)(step.step_response)
    elif point == "snapshot":
        from servotool.motion.jogger import Jogger

        Jogger.snapshot = _once(lambda *_: True, before=True)(Jogger.snapshot)  # type: ignore[method-assign]
    elif point == "protections":
        import servotool.motion.protect as protect

        protect.apply = _once(lambda *_: True, before=False)(protect.apply)
    else:
        raise SystemExit(f"interrupt_at: the point is one of {', '.join(POINTS)}, not {point!r}")


def main() -> None:
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    point = sys.argv[1]
    arm(point)
    sys.argv = ["servotool", *sys.argv[2:]]
    from servotool.cli.main import run

    run()


if __name__ == "__main__":
    main()
