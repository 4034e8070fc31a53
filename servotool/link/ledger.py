"""What an RTU line may still deliver: the frames heard lately (whose copies may follow) and the replies owed by tries
that failed (which may come later than any timeout). link/exchange.py asks it whether a reply could be a stray one.

Requests are told apart by their identity (`Rid`): a read's unit, address, register count and the write epoch of its
registers (so that a reply read before a write never stands for one read after it); a write's by what its
acknowledgement shows.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

# A copy of a frame (a duplicate from a gateway or a retrying drive, an echo) comes within this long after it. The
# fault proxy's gaps reach 50 ms, real lines 20 ms (issue 30).
COPY_WINDOW = 0.1
# A reply owed by a failed try is expected for this many timeouts (and at least OWED_MIN_S): later than the
# timeout and the late-reply window a silent try already waits, and later than a gateway's queue releases one.
OWED_TIMEOUTS, OWED_MIN_S = 10, 2.0

Rid = tuple[int, ...]  # a request's identity: (unit, fc, address, count, epoch) or (unit, fc, address, value|count)
Shape = tuple[int, ...]  # what a reply's head shows: (unit, fc, byte count) for a read, the whole frame for a write


def shape_of(frame: bytes) -> Shape:
    """The shape of a reply frame: a read's by its unit, function and byte count; a write acknowledgement or an
    exception by all its bytes (what they echo is all they show)."""
    if len(frame) > 5 and frame[1] in (1, 2, 3, 4):
        return (frame[0], frame[1], frame[2])
    return tuple(frame)


@dataclass
class Ledger:
    """Frames heard within COPY_WINDOW (by content, with the request each answered) and replies owed within
    `owed_s` (by shape, with the request that owes it)."""

    owed_s: float = OWED_MIN_S
    _heard: dict[bytes, tuple[Rid, float]] = field(default_factory=dict)
    _order: deque[tuple[float, bytes]] = field(default_factory=deque)
    _owed: dict[Shape, dict[Rid, list[float]]] = field(default_factory=dict)  # rid -> [replies owed, until when]

    def heard(self, frame: bytes, rid: Rid | None, now: float) -> None:
        """A frame came (rid: the request it was taken to answer; None for a stray one, which keeps the request of
        a frame it copies)."""
        self._expire(now)
        if rid is None and (known := self._heard.get(frame)) is not None:
            rid = known[0]
        self._heard[frame] = (rid or (), now)
        self._order.append((now, frame))

    def copy_of(self, frame: bytes, now: float) -> Rid | None:
        """The request whose reply this frame repeats byte for byte, when one was heard within COPY_WINDOW (() for
        a stray frame); None when it is no copy."""
        self._expire(now)
        found = self._heard.get(frame)
        return found[0] if found is not None else None

    def owe(self, shape: Shape, rid: Rid, now: float) -> None:
        """A try of `rid` ended without its reply, or with a reply that may have been another's: it may still come.
        Each try owes its own reply (two failed tries of one read may both be answered late)."""
        owed = self._owed.setdefault(shape, {}).setdefault(rid, [0, 0.0])
        owed[0] += 1
        owed[1] = max(owed[1], now + self.owed_s)

    def pay(self, frame: bytes, rid: Rid = ()) -> None:
        """A frame came that may be an owed reply (a stray one that is no copy, or one of two answers that
        disagree): one reply owed with its shape by a request other than `rid` (the one owed longest) is taken to be
        it; for an exception frame, one owed by any read of its unit."""
        shapes = [s for s in self._owed if s and s[0] == frame[0]] if frame[1] & 0x80 else [shape_of(frame)]
        oldest: tuple[float, Shape, Rid] | None = None
        for shape in shapes:
            for other, (_, until) in self._owed.get(shape, {}).items():
                if other != rid and (oldest is None or until < oldest[0]):
                    oldest = (until, shape, other)
        if oldest is not None:
            owed = self._owed[oldest[1]]
            owed[oldest[2]][0] -= 1
            if owed[oldest[2]][0] <= 0:
                del owed[oldest[2]]

    def owed_by_other(self, shape: Shape, rid: Rid, now: float) -> bool:
        """Whether a reply of this shape is owed to another request (then one arriving now may be that)."""
        owed = self._owed.get(shape)
        if not owed:
            return False
        for other, (_, until) in list(owed.items()):
            if until < now:
                del owed[other]
            elif other != rid:
                return True
        return False

    def owed_by_other_at(self, unit: int, now: float, rid: Rid) -> bool:
        """Whether any reply is owed by another request to this unit (an exception reply could be its)."""
        return any(s and s[0] == unit and self.owed_by_other(s, rid, now) for s in list(self._owed))

    def _expire(self, now: float) -> None:
        while self._order and now - self._order[0][0] > COPY_WINDOW:
            t, frame = self._order.popleft()
            if (found := self._heard.get(frame)) is not None and found[1] == t:
                del self._heard[frame]
