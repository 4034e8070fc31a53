"""Request and reply on an RTU line, which has no transaction id: accept only a reply that provably answers.

Every reply is matched to its request (unit, function, byte count; a write's echoed address and value), and bytes
after it make it suspect. After a fault the line is left to go quiet (a late reply's window) and flushed. A read
that follows a fault is confirmed by a second read that must agree, when a stale reply of the same shape could
stand in for it; a failed write is read back before it is sent again, and a write that is not safe to repeat (an Fn
trigger) never is. Every operation has a bounded number of tries.

The promise holds for replies that come within the late window (one timeout) after their timeout; a later reply
is caught only when it stands in for a read that confirmation checks, so a drive slower than that needs a longer
--timeout.
"""

from __future__ import annotations

from collections import deque
from typing import Protocol

from servotool.clock import Clock, RealClock
from servotool.errors import DeviceError, ModbusException
from servotool.link.ports import Trace
from servotool.link.rtu import READ, WRITE_MANY, WRITE_ONE, NotAnswer, Request

# Silence that ends a frame. RTU's 3.5 characters, but USB-serial adapters and TCP gateways deliver bytes in
# bursts (an FTDI's latency timer holds them up to 16 ms), so a frame is only taken as over after this long.
FRAME_GAP = 0.05


class Wire(Protocol):
    """A byte pipe to the line."""

    def send(self, data: bytes) -> None: ...
    def recv(self, timeout: float) -> bytes:
        """Bytes that arrived within timeout (b"" for none); ConnectionError when the line is gone."""
        ...


class LineFault(Exception):
    """One try got no reply that answers it: silent, garbled, or stray (a valid frame for another request)."""

    def __init__(self, kind: str, received: int, why: str = "") -> None:
        super().__init__(kind)
        self.kind, self.received, self.why = kind, received, why


class _Op:
    """One read or write operation: its tries, its faults and its budget."""

    def __init__(self, what: str, retries: int, timeout: float, outcome: str = "") -> None:
        self.what, self.retries, self.timeout, self.outcome = what, retries, timeout, outcome
        self.tries = 0
        self.faults = 0
        self.troubled = False  # a fault or stray bytes: the line's replies need proof

    def begin(self) -> None:
        if self.tries >= 2 * (self.retries + 2):
            error = DeviceError(
                f"{self.what}: no two reads in a row agreed after {self._tries()} (a value that "
                f"changes by itself, or stray replies on the line); nothing was used"
            )
            error.fault = "unsettled"  # the line answered: a live value (a turning motor's speed) may differ each time
            raise error
        self.tries += 1

    def spend(self, fault: LineFault) -> None:
        self.faults += 1
        self.troubled = True
        if self.faults > self.retries:
            raise self.error(fault)

    def _tries(self) -> str:
        return f"{self.tries} tr{'y' if self.tries == 1 else 'ies'}"

    def error(self, fault: LineFault) -> DeviceError:
        tries = self._tries()
        if fault.kind == "silent":
            text = (
                f"no response within {self.timeout:g} s after {tries} "
                f"(wrong unit id, baud/parity, wiring, or the drive is off)"
            )
        elif fault.kind == "garbled":
            text = (
                f"garbled response after {tries}, {fault.received} bytes with a bad CRC or framing "
                f"(noise, termination, baud/parity mismatch, or two masters on the line)"
            )
        else:
            text = (
                f"no reply that answers it after {tries}, last {fault.why} (a late or repeated reply, an "
                f"echoing adapter, or two masters on the line)"
            )
        error = DeviceError(f"{self.what}: {text}{'; ' + self.outcome if self.outcome else ''}")
        error.fault = fault.kind
        return error


class Exchange:
    """Reads and writes over a Wire with reply matching, quiet-and-flush after faults, and confirmation."""

    def __init__(
        self,
        wire: Wire,
        *,
        timeout: float,
        retries: int,
        settle: float = 0.0,
        turnaround: float = 0.0,
        echo: bool | None = False,
        trace: Trace | None = None,
        clock: Clock | None = None,
    ) -> None:
        self.wire, self.timeout, self.retries, self.settle = wire, timeout, retries, settle
        self.turnaround = turnaround  # quiet after the last byte heard, before a request
        self._heard = -float("inf")  # when the last byte came
        self.echo = echo  # the adapter echoes what we send; None: find out
        self.late_window = timeout  # how long after its timeout a late reply may still come
        self.flush_gap = FRAME_GAP  # the silence that ends what is left of a failed try
        self.trace, self.clock = trace, clock or RealClock()
        self.requests = 0
        self._suspect = False  # the last operation met a fault: confirm the next reads
        self._recent: deque[Request] = deque(maxlen=8)

    # ----- operations ----------------------------------------------------------------------------------------
    def read(self, unit: int, address: int, count: int) -> list[int]:
        op = _Op(
            f"read {count} register(s) at {address} (0x{address:04X}) from unit {unit}", self.retries, self.timeout
        )
        try:
            return self._read(Request(unit, READ, address, count), op)
        finally:
            self._suspect = op.troubled

    def write(
        self, unit: int, address: int, values: list[int], *, multiple: bool = True, idempotent: bool = True
    ) -> None:
        fc = WRITE_ONE if len(values) == 1 and not multiple else WRITE_MANY
        req = Request(unit, fc, address, len(values), tuple(values))
        outcome = (
            "the drive may or may not hold the new value"
            if idempotent
            else "it may or may not have run; not sent again, since running it twice is not safe"
        )
        op = _Op(
            f"write {len(values)} register(s) at {address} (0x{address:04X}) to unit {unit}",
            self.retries,
            self.timeout,
            outcome,
        )
        if self.echo is None and fc == WRITE_ONE:
            self._probe_echo(unit, address)
        refused: int | None = None
        try:
            while True:
                try:
                    self._attempt(req, op)
                    return
                except LineFault as fault:
                    if not idempotent:
                        raise op.error(fault) from None
                except ModbusException as exc:
                    # After a fault, a stale exception reply could stand in for this write's: an idempotent
                    # write is refused only when the drive says so twice in a row.
                    if not idempotent or not (self._suspect or op.troubled) or exc.code == refused:
                        raise
                    refused = exc.code
                    continue
                if self._holds(req, op):
                    return
        finally:
            self._suspect = op.troubled

    def _read(self, req: Request, op: _Op) -> list[int]:
        previous: list[int] | int | None = None
        while True:
            try:
                words = self._attempt(req, op)
            except LineFault:
                previous = None
                continue
            except ModbusException as exc:
                # An exception reply names no address, so after a fault a stale one could stand in for this
                # read's reply: believe it (an entry the drive lacks, say) only when it comes twice in a row.
                if not (self._suspect or op.troubled) or exc.code == previous:
                    raise
                previous = exc.code
                continue
            if not (self._suspect or op.troubled) or not self._ambiguous(req) or words == previous:
                return words
            previous = words

    def _probe_echo(self, unit: int, address: int) -> None:
        """Find out whether the adapter echoes before a first FC06 write, whose reply repeats the request (one copy
        alone cannot tell echo from reply): any answer to a one-register read tells, even an exception."""
        try:
            self._attempt(Request(unit, READ, address, 1), _Op("echo probe", 0, self.timeout))
        except (LineFault, DeviceError):  # ModbusException too: the reply's head already told
            pass

    def _holds(self, req: Request, op: _Op) -> bool:
        """Whether the drive already holds what a failed write sent (then sending it again is not needed)."""
        try:
            return self._read(Request(req.unit, READ, req.address, req.count), op) == list(req.values)
        except ModbusException:
            return False  # not readable here: cannot tell, and the write is safe to repeat

    def _ambiguous(self, req: Request) -> bool:
        """Whether a stale reply to a recent request could pass for this read's reply (same unit and register
        count, other address). A stale reply to the very same read carries the same registers."""
        return any(
            r.fc == READ and r.unit == req.unit and r.count == req.count and r.address != req.address
            for r in self._recent
        )

    # ----- one try ------------------------------------------------------------------------------------------
    def _attempt(self, req: Request, op: _Op) -> list[int]:
        try:
            return self._try(req, op)
        except OSError as exc:  # ConnectionError too: the port or socket is gone
            raise DeviceError(f"{op.what}: link lost ({exc or type(exc).__name__})") from None

    def _try(self, req: Request, op: _Op) -> list[int]:
        op.begin()
        if self._take_pending(0.0):
            op.troubled = True  # bytes nobody asked for: a late or repeated reply
        if (wait := self._heard + self.turnaround - self.clock.now()) > 0:
            self.clock.sleep(wait)
        self.requests += 1
        self._recent.append(req)
        sent_at = self.clock.now()
        if self.trace:
            self.trace(True, req.frame)
        self.wire.send(req.frame)
        try:
            frame, extra = self._receive(req, sent_at + self.timeout)
            try:
                words = req.answer(frame, op.what)
            except NotAnswer as exc:
                raise _fault(exc, len(frame) + len(extra)) from None
            if extra:
                raise LineFault("extra", len(frame) + len(extra), f"{len(extra)} more bytes after the reply")
            return words
        except LineFault as exc:
            fault = exc
        self._quiet(fault, sent_at)
        op.spend(fault)
        raise fault

    def _receive(self, req: Request, deadline: float) -> tuple[bytes, bytes]:
        """(reply frame, bytes after it) for req; LineFault when none came in time, NotAnswer when the bytes
        show they answer something else."""
        buf = self._skip_echo(req, deadline)
        while True:
            try:
                n = req.reply_length(buf)
            except NotAnswer as exc:
                raise _fault(exc, len(buf)) from None
            if n is not None and len(buf) >= n:
                return buf[:n], buf[n:] + self._take_pending(self.settle)
            left = deadline - self.clock.now()
            if left <= 0:
                raise LineFault("garbled" if buf else "silent", len(buf), "a partial reply")
            chunk = self._recv(min(left, FRAME_GAP) if buf else left)
            if buf and not chunk:
                raise LineFault("garbled", len(buf), "a partial reply")  # the line went quiet mid-frame
            buf += chunk

    def _skip_echo(self, req: Request, deadline: float) -> bytes:
        """Read back our own transmission when the adapter echoes it; the bytes after it."""
        if self.echo is False:
            return b""
        sent, buf = req.frame, b""
        while len(buf) < len(sent) and sent.startswith(buf):
            left = deadline - self.clock.now()
            if left <= 0:
                return buf
            buf += self._recv(left)
        if not buf.startswith(sent):
            if self.echo is None and req.fc != WRITE_ONE:
                self.echo = False
            return buf
        if self.echo is None and req.fc == WRITE_ONE:
            # An FC06 reply repeats the request: one copy alone is the echo or the reply, which cannot be told.
            buf += self._take_pending(max(0.0, deadline - self.clock.now()), until=len(sent) * 2 - len(buf))
            if len(buf) < 2 * len(sent):
                raise LineFault("stray", len(buf), "one copy of a write that may be an echo")
        self.echo = True
        return buf[len(sent) :]

    # ----- the line -----------------------------------------------------------------------------------------
    def _quiet(self, fault: LineFault, sent_at: float) -> None:
        """Drop what is left of a failed try: a garbled or repeated reply is over once the line is quiet; after
        another request's reply, the real one may still come (until the timeout); after silence, a late reply
        (until the late-reply window has passed)."""
        if fault.kind in ("silent", "stray"):
            until = sent_at + self.timeout + (self.late_window if fault.kind == "silent" else 0.0)
            while (left := until - self.clock.now()) > 0:
                self._recv(left)
        self._take_pending(max(self.settle, self.flush_gap))

    def _take_pending(self, quiet: float, until: int = 0) -> bytes:
        """Bytes already waiting, and those that follow within `quiet` s of each other (or until `until` came)."""
        data = b""
        while chunk := self._recv(quiet):
            data += chunk
            if until and len(data) >= until:
                break
        return data

    def _recv(self, timeout: float) -> bytes:
        data = self.wire.recv(max(0.0, timeout))
        if data:
            self._heard = self.clock.now()
            if self.trace:
                self.trace(False, data)
        return data


def _fault(exc: NotAnswer, received: int) -> LineFault:
    return LineFault("garbled" if exc.garbled else "stray", received, str(exc))
