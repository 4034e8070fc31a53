"""Hold-to-run, as on vendor panels: the motor moves only while a direction key is held.

A terminal reports a held key as the key's first press, then, after the keyboard's repeat delay (typically
250-600 ms), a repeat about every 30 ms. Motion therefore continues across the first repeat delay, and stops
within one beat once the repeats stop (the key was let go). The toggle mode (a key starts, space stops) is kept.
"""

from __future__ import annotations

from servotool.clock import Clock

FIRST_REPEAT_S = 0.7  # longest usual keyboard repeat delay (and then some)


class HoldToRun:
    """Turns key events into a direction: feed it each poll's key (+1, -1, 0 for stop, None for no key)."""

    def __init__(self, clock: Clock, beat_s: float, first_repeat_s: float = FIRST_REPEAT_S) -> None:
        self.clock = clock
        self.beat_s = beat_s
        self.first_repeat_s = first_repeat_s
        self.direction = 0
        self._pressed_at = 0.0
        self._last_key = 0.0
        self._repeating = False

    def key(self, direction: int | None) -> int:
        """The direction to command after this poll."""
        now = self.clock.now()
        if direction is None:
            grace = self.beat_s if self._repeating else self.first_repeat_s
            if self.direction and now - self._last_key > grace:
                self.direction = 0  # let go: no repeat within the grace time
            return self.direction
        if direction != self.direction or direction == 0:
            self.direction = direction
            self._pressed_at = now
            self._repeating = False
        else:
            self._repeating = True
        self._last_key = now
        return self.direction
