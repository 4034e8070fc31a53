"""Request and reply on an RTU line, which has no transaction id: use only a reply proven to answer its request.

The contract. A frame is taken as the answer to a request when its head and CRC fit the request (unit, function,
byte count; a write's echoed address and value) and nothing on the line says it may be another's:

1. A read that follows one repeating a read made within the copy window (a monitor's, a trace's) differs from it in
   reply length wherever the profile lets a read widen by an adjacent entry (`spare`): a copy of that read's reply,
   or its own reply that such a copy stood in for (point 4), cannot fit.
2. A frame that repeats, byte for byte, one heard within the copy window (link/ledger.py) for another request (or
   for the same read before a write to its registers) may be that frame's copy: the read is confirmed.
3. A try that failed (or that Ctrl-C interrupted) owes its reply, which may come later than any timeout: a reply of
   that shape for another request is confirmed, and reads pick a width that no owed reply has.
4. Bytes before a request or after a reply are a fault of the operation, and faults leave the line to go quiet and
   be flushed; on a line that has shown faults, a read whose reply repeats its own last one is confirmed too.
5. A confirmation is another read, at another width where one is allowed. An unambiguous confirmation stands; two
   ambiguous ones must agree; a disagreement is a fault.

So, as long as copies come within the copy window and late replies within the owed window (link/ledger.py), a stray
frame can stand in for a reply only when it answers the same registers, read in the same write epoch: never another
request's value. A write's acknowledgement shows only its address and value or count; what a write stored is proven
by reading it back (drive.py). Every operation has a bounded number of tries; a failed write is read back before it
is sent again, and a write that is not safe to repeat (an Fn trigger) never is.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Protocol

from servotool.clock import Clock, RealClock
from servotool.errors import DeviceError, ModbusException
from servotool.link.crc import crc_ok, with_crc
from servotool.link.ledger import COPY_WINDOW, OWED_MIN_S, OWED_TIMEOUTS, Ledger, Rid, shape_of
from servotool.link.ports import Trace
from servotool.link.rtu import (
    READ,
    READ_COILS,
    READ_INPUT,
    WRITE_COIL,
    WRITE_COILS,
    WRITE_MANY,
    WRITE_ONE,
    NotAnswer,
    Request,
)

# Silence that ends a frame. RTU's 3.5 characters, but USB-serial adapters and TCP gateways deliver bytes in
# bursts (an FTDI's latency timer holds them up to 16 ms), so a frame is only taken as over after this long.
FRAME_GAP = 0.05
GAP_CHARS = 7  # the 3.5-character silences before a request and before its reply


class Wire(Protocol):
    """A byte pipe to the line."""

    def send(self, data: bytes) -> None: ...
    def recv(self, timeout: float) -> bytes:
        """Bytes that arrived within timeout (b"" for none); ConnectionError when the line is gone."""
        ...


class LineFault(Exception):
    """One try got no reply that answers it: silent, garbled, stray (a valid frame for another request), or a
    confirmation that disagrees."""

    def __init__(self, kind: str, received: int, why: str = "", data: bytes = b"") -> None:
        super().__init__(kind)
        self.kind, self.received, self.why = kind, received, why
        self.data = data  # the bytes this try got, when they may hold another request's frame


@dataclass(frozen=True)
class _Reply:
    """One try's answer: registers (writes: []) or an exception code, its frame, and whether it may be another's."""

    words: list[int]
    code: int | None
    frame: bytes
    ambiguous: bool


Answer = list[int] | int  # registers, or the code of an exception reply
Held = tuple[Answer, Request, _Reply]  # an ambiguous answer awaiting its confirmation, with its request and reply


class _Op:
    """One read or write operation: its tries, its faults and its budget."""

    def __init__(self, what: str, retries: int, timeout: float, outcome: str = "", wire: str = "") -> None:
        self.what, self.retries, self.timeout, self.outcome, self.wire = what, retries, timeout, outcome, wire
        self.tries = 0
        self.faults = 0
        self.repeating = False  # a read of registers read within the copy window (a monitor's, a trace's)

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
        if self.faults > self.retries:
            raise self.error(fault)

    def _tries(self) -> str:
        return f"{self.tries} tr{'y' if self.tries == 1 else 'ies'}"

    def error(self, fault: LineFault) -> DeviceError:
        tries = self._tries()
        if fault.kind == "silent":
            text = (
                f"no response within {self.timeout:g} s{self.wire} after {tries} "
                f"(wrong unit id, baud/parity, wiring, or the drive is off)"
            )
        elif fault.kind == "garbled":
            text = (
                f"garbled response after {tries}, {fault.received} bytes with a bad CRC or framing "
                f"(noise, termination, baud/parity mismatch, or two masters on the line)"
            )
        elif fault.kind == "disagree":
            text = f"replies that disagree after {tries} ({fault.why}: stray replies on the line, or two masters)"
        else:
            text = (
                f"no reply that answers it after {tries}, last {fault.why} (a late or repeated reply, an "
                f"echoing adapter, or two masters on the line)"
            )
        error = DeviceError(f"{self.what}: {text}{'; ' + self.outcome if self.outcome else ''}")
        error.fault = fault.kind
        return error


class Exchange:
    """Reads and writes over a Wire with reply matching, a ledger of what the line may still deliver, quiet-and-flush
    after faults, and confirmation."""

    def __init__(
        self,
        wire: Wire,
        *,
        timeout: float,
        retries: int,
        settle: float = 0.0,
        turnaround: float = 0.0,
        echo: bool | None = False,
        char_s: float = 0.0,
        baud: int = 0,
        trace: Trace | None = None,
        clock: Clock | None = None,
    ) -> None:
        self.wire, self.timeout, self.retries, self.settle = wire, timeout, retries, settle
        self.turnaround = turnaround  # quiet after the last byte heard, before a request
        self.char_s, self.baud = char_s, baud  # a character's time on the line (0: not known), for the deadlines
        self._heard_at = -float("inf")  # when the last byte came
        self.echo = echo  # the adapter echoes what we send; None: find out
        self.late_window = timeout  # how long after its deadline a late reply is waited for after silence
        self.flush_gap = FRAME_GAP  # the silence that ends what is left of a failed try
        self.trace, self.clock = trace, clock or RealClock()
        self.requests = 0
        self.ledger = Ledger(owed_s=max(OWED_MIN_S, OWED_TIMEOUTS * timeout))
        self._previous: dict[int, tuple[int, bool]] = {}  # by unit: the last read's reply byte count, and whether
        # it repeated a read made within the copy window
        self._asked: dict[tuple[int, int, int], float] = {}  # (unit, address, count) -> when it was last read
        self._written: dict[tuple[int, int], int] = {}  # (unit, address) -> the number of the last write to it
        self._writes = 0
        self._narrow: set[tuple[int, int, int]] = set()  # reads whose widening met an exception
        self._trouble_until = -float("inf")  # bytes nobody asked for or a garbled reply were met lately: copies of a
        # read's own reply are confirmed, and so are exception replies
        self._sent: deque[bytes] = deque(maxlen=16)  # the latest requests, whose echoes may come back

    # ----- operations ----------------------------------------------------------------------------------------
    def read(
        self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0), fc: int = READ
    ) -> list[int]:
        """`count` registers at `address` (fc 3 holding, 4 input registers; fc 1 coils, 2 discrete inputs, as bits
        0/1); `spare` = registers before and after that may be read too (a whole adjacent entry each), to give this
        read's reply another length than the replies around it."""
        kind = {1: "coil(s)", 2: "discrete input(s)", READ_INPUT: "input register(s)"}.get(fc, "register(s)")
        what = f"read {count} {kind} at {address} (0x{address:04X}) from unit {unit}"
        op = self._op(what, Request(unit, fc, address, count))
        return self._read(unit, address, count, spare, op, fc)

    def _read(self, unit: int, address: int, count: int, spare: tuple[int, int], op: _Op, fc: int = READ) -> list[int]:
        now, key = self.clock.now(), (unit, address, count)
        op.repeating = now - self._asked.get(key, -float("inf")) <= COPY_WINDOW
        self._asked[key] = now
        held: Held | None = None
        while True:
            req = self._shape(unit, address, count, spare, held[1] if held else None, fc)
            try:
                reply = self._attempt(req, op)
            except LineFault:
                held = None
                continue
            if reply.code is not None and req.count != count:
                self._narrow.add((unit, address, count))  # the widening met it: ask for the registers alone
                held = None
                continue
            offset = address - req.address
            answer = reply.code if reply.code is not None else reply.words[offset : offset + count]
            if held is not None and answer != held[0]:
                self._disagree(held, req, reply, answer, op)  # a fault: one of the two was another's reply
                if reply.ambiguous:
                    held = None
                    continue
            elif held is None and reply.ambiguous:
                held = (answer, req, reply)
                continue
            if isinstance(answer, int):
                raise ModbusException(answer, op.what)
            return answer

    def _disagree(self, held: Held, req: Request, reply: _Reply, answer: Answer, op: _Op) -> None:
        """A confirmation that disagrees with the answer it confirms: a fault (one of the two may have been another
        request's reply, or a live value moved). The first request's own reply may still come. A confirmation no
        more certain than the first answer leaves both dropped and the line to go quiet, and spends a try's budget;
        an unambiguous one stands, and the fault is only counted."""
        first, first_req, _ = held
        fault = LineFault("disagree", len(reply.frame), f"{_said(first)}, then {_said(answer)}")
        self._owe(first_req)  # no mark of a troubled line: a live value may simply have moved between the reads
        if not reply.ambiguous:
            op.faults += 1
            return
        self._owe(req)
        self._quiet(fault, self.clock.now())
        op.spend(fault)

    def write(
        self,
        unit: int,
        address: int,
        values: list[int],
        *,
        multiple: bool = True,
        idempotent: bool = True,
        coils: bool = False,
    ) -> None:
        """Write registers (FC06 for one unless `multiple`, else FC16), or with `coils` bits 0/1 (FC05, FC15)."""
        single = len(values) == 1 and not multiple
        fc = (WRITE_COIL if single else WRITE_COILS) if coils else WRITE_ONE if single else WRITE_MANY
        req = Request(unit, fc, address, len(values), tuple(values))
        outcome = (
            "the drive may or may not hold the new value"
            if idempotent
            else "it may or may not have run; not sent again, since running it twice is not safe"
        )
        what = "coil(s)" if coils else "register(s)"
        op = self._op(
            f"write {len(values)} {what} at {address} (0x{address:04X}) to unit {unit}",
            req,
            outcome,
        )
        if self.echo is None and req.repeated:
            self._probe_echo(unit, address)
        refused: int | None = None
        while True:
            try:
                reply = self._attempt(req, op)
            except LineFault as fault:
                if not idempotent:
                    raise op.error(fault) from None
            else:
                if reply.code is not None:
                    # A stray exception reply could stand in for this write's: an idempotent write is refused only
                    # when the drive says so twice in a row.
                    if not idempotent or not reply.ambiguous or reply.code == refused:
                        raise ModbusException(reply.code, op.what)
                    refused = reply.code
                    continue
                if not reply.ambiguous:
                    return
                fault = LineFault("stray", len(reply.frame), "an acknowledgement that may be an earlier write's")
                self._owe(req)
                if not idempotent:
                    raise op.error(fault) from None
                op.spend(fault)
            if self._holds(req, op):
                return

    def _op(self, what: str, req: Request, outcome: str = "") -> _Op:
        """An operation on `req`; where the frames take a good part of the timeout on the wire, its silence error
        says that they were waited for on top of it."""
        wire = ""
        if (wire_s := self._wire_time(req)) >= 0.25 * self.timeout:
            wire = f" beyond the {wire_s * 1000:.0f} ms the request and reply take on the wire at {self.baud} baud,"
        return _Op(what, self.retries, self.timeout, outcome, wire)

    def _probe_echo(self, unit: int, address: int) -> None:
        """Find out whether the adapter echoes before a first FC06 write, whose reply repeats the request (one copy
        alone cannot tell echo from reply): any answer to a one-register read tells, even an exception."""
        try:
            self._attempt(Request(unit, READ, address, 1), _Op("echo probe", 0, self.timeout))
        except (LineFault, DeviceError):
            pass

    def _holds(self, req: Request, op: _Op) -> bool:
        """Whether the drive already holds what a failed write sent (then sending it again is not needed)."""
        try:
            fc = READ_COILS if req.fc in (WRITE_COIL, WRITE_COILS) else READ
            return self._read(req.unit, req.address, req.count, (0, 0), op, fc) == list(req.values)
        except ModbusException:
            return False  # not readable here: cannot tell, and the write is safe to repeat

    # ----- which request, and who may answer it -------------------------------------------------------------
    def _shape(
        self, unit: int, address: int, count: int, spare: tuple[int, int], avoid: Request | None, fc: int = READ
    ) -> Request:
        """The read to send for `count` registers at `address`: of the widths `spare` allows, the narrowest whose reply
        length no owed reply has and that differs from an answer being confirmed and from the last read's when that
        one repeated (contract point 1)."""
        before, after = (0, 0) if (unit, address, count) in self._narrow else spare
        if not before and not after:
            return Request(unit, fc, address, count)
        now = self.clock.now()
        previous = self._previous.get(unit)
        best: tuple[tuple[bool, ...], Request] | None = None
        for lead, tail in dict.fromkeys(((0, 0), (0, after), (before, 0), (before, after))):
            req = Request(unit, fc, address - lead, count + lead + tail)
            rid, shape = self._rid(req), (unit, fc, req.data_bytes)
            score = (
                self.ledger.owed_by_other(shape, rid, now),
                avoid is not None and req.count == avoid.count,
                previous is not None and previous[1] and req.data_bytes == previous[0],
            )
            if best is None or score < best[0]:
                best = (score, req)
            if not any(score):
                break
        assert best is not None
        return best[1]

    def _rid(self, req: Request) -> Rid:
        """A request's identity: a read's includes the number of the last write to its registers; a write's is what
        its acknowledgement shows (an FC16 one echoes no values, so a copy of one for the same registers fits: what
        a write stored is proven by reading it back, drive.Drive.write_verified)."""
        if not req.reads:
            return (req.unit, req.fc, req.address, req.values[0] if req.repeated else req.count)
        epoch = 0
        if self._written:
            get = self._written.get
            epoch = max(get((req.unit, a), 0) for a in range(req.address, req.address + req.count))
        return (req.unit, req.fc, req.address, req.count, epoch)

    def _ambiguous(self, req: Request, rid: Rid, frame: bytes, now: float) -> bool:
        """Whether the frame that fits `req` may be another request's reply or an old one (contract points 2-4)."""
        copied = self.ledger.copy_of(frame, now)
        if copied is not None and copied != rid:
            return True
        shape = shape_of(frame)
        if frame[1] & 0x80:
            if self.ledger.owed_by_other_at(req.unit, now, rid) or now < self._trouble_until:
                return True
        elif self.ledger.owed_by_other(shape, rid, now):
            return True
        # A copy of this read's own earlier reply, on a line that has shown faults: the same registers, but maybe a
        # moment old, and its own reply may follow (point 4).
        return copied is not None and req.reads and now < self._trouble_until

    def _owe(self, req: Request) -> None:
        """The request's reply may still come (a failed try, or a reply that may have been another's)."""
        if req.reads:
            shape: tuple[int, ...] = (req.unit, req.fc, req.data_bytes)
        else:
            shape = shape_of(req.frame if req.repeated else with_crc(req.frame[:6]))
        self.ledger.owe(shape, self._rid(req), self.clock.now())

    def _stray(self, data: bytes) -> None:
        """Bytes nobody asked for: record the frames among them (copies of them are then known) and let each one
        that is no copy pay the reply owed with its shape."""
        now = self.clock.now()
        self._trouble_until = now + self.ledger.owed_s
        for frame in _frames(data):
            if self.ledger.copy_of(frame, now) is None:
                self.ledger.pay(frame)
            self.ledger.heard(frame, None, now)

    # ----- one try ------------------------------------------------------------------------------------------
    def _attempt(self, req: Request, op: _Op) -> _Reply:
        try:
            return self._try(req, op)
        except OSError as exc:  # ConnectionError too: the port or socket is gone
            raise DeviceError(f"{op.what}: link lost ({exc or type(exc).__name__})") from None

    def _try(self, req: Request, op: _Op) -> _Reply:
        op.begin()
        if pending := self._take_pending(0.0):
            self._stray(pending)  # bytes nobody asked for: a late or repeated reply
        if (wait := self._heard_at + self.turnaround - self.clock.now()) > 0:
            self.clock.sleep(wait)
        rid = self._rid(req)
        self.requests += 1
        if req.reads:
            self._previous[req.unit] = (req.data_bytes, op.repeating)
        else:
            self._writes += 1
            for a in range(req.address, req.address + req.count):
                self._written[(req.unit, a)] = self._writes
        sent_at = self.clock.now()
        deadline = sent_at + self.timeout + self._wire_time(req)
        if self.trace:
            self.trace(True, req.frame)
        self._sent.append(req.frame)
        try:
            self.wire.send(req.frame)
            frame, extra = self._receive(req, deadline)
            try:
                words = req.answer(frame, op.what)
                code = None
            except ModbusException as exc:
                words, code = [], exc.code
            except NotAnswer as exc:
                raise _fault(exc, len(frame) + len(extra), frame + extra) from None
            now = self.clock.now()
            if extra and extra != frame * (len(extra) // len(frame)):
                self.ledger.heard(frame, rid, now)
                raise LineFault("extra", len(frame) + len(extra), f"{len(extra)} more bytes after the reply", extra)
            if extra:  # copies of the reply itself: a repeating line, but this reply stands as its own copies do
                self._trouble_until = now + self.ledger.owed_s
            ambiguous = self._ambiguous(req, rid, frame, now)
            self.ledger.heard(frame, rid, now)
            return _Reply(words, code, frame, ambiguous)
        except LineFault as exc:
            fault = exc
        except KeyboardInterrupt:
            # Interrupted (Ctrl-C, a terminate signal) with the reply perhaps on its way: it is owed as a failed
            # try's is, so that it cannot pass for the answer to the next request of its shape.
            self._owe(req)
            raise
        if fault.kind != "silent" or fault.data:
            # Silence alone shows nothing on the line that repeats or comes late: the reply it owes is in the ledger,
            # and one that comes within the late window is a stray frame that marks the line (a probe of ids that
            # are silent by design, before a line speed's trial, does not make every repeated read confirmed).
            self._trouble_until = self.clock.now() + self.ledger.owed_s
        self._owe(req)
        self._quiet(fault, deadline)
        op.spend(fault)
        raise fault

    def _wire_time(self, req: Request) -> float:
        """Seconds the request and its longest reply take on the line, at the baud rate when it is known."""
        if not self.char_s:
            return 0.0
        reply = 5 + req.data_bytes if req.reads else 8
        return (len(req.frame) + reply + GAP_CHARS) * self.char_s

    def _receive(self, req: Request, deadline: float) -> tuple[bytes, bytes]:
        """(reply frame, bytes after it) for req; LineFault when none came in time, NotAnswer when the bytes
        show they answer something else."""
        buf = self._skip_echo(req, deadline)
        while True:
            try:
                n = req.reply_length(buf)
            except NotAnswer as exc:
                if (rest := self._skip_stray(buf, deadline)) is None:
                    raise _fault(exc, len(buf), buf) from None
                buf = rest  # a whole frame for another request, set aside: the reply may still follow
                continue
            if n is not None and len(buf) >= n:
                return buf[:n], buf[n:] + self._take_pending(self.settle)
            left = deadline - self.clock.now()
            if left <= 0:
                raise LineFault("garbled" if buf else "silent", len(buf), "a partial reply")
            chunk = self._recv(min(left, FRAME_GAP) if buf else left)
            if buf and not chunk:
                raise LineFault("garbled", len(buf), "a partial reply")  # the line went quiet mid-frame
            buf += chunk

    def _skip_stray(self, buf: bytes, deadline: float) -> bytes | None:
        """What follows the whole valid frame for another request (an echo of one of ours, a late, repeated or
        foreign reply) that `buf` starts with, once it is in and recorded; None when it is no such frame."""
        echoed = next((f for f in self._sent if buf.startswith(f[: len(buf)])), None)
        while True:
            if echoed is not None and not buf.startswith(echoed[: len(buf)]):
                echoed = None  # it only began like one of our requests
            n = len(echoed) if echoed is not None else _frame_length(buf)
            if n is not None and len(buf) >= n:
                break
            left = deadline - self.clock.now()
            if left <= 0 or not (chunk := self._recv(min(left, FRAME_GAP))):
                return None
            buf += chunk
        if echoed is not None and buf.startswith(echoed):
            self._trouble_until = self.clock.now() + self.ledger.owed_s
            return buf[n:]
        if not crc_ok(buf[:n]):
            return None
        self._stray(buf[:n])
        return buf[n:]

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
            if self.echo is None and not req.repeated:
                self.echo = False
            return buf
        if self.echo is None and req.repeated:
            # An FC05/FC06 reply repeats the request: one copy alone is the echo or the reply, which cannot be told.
            buf += self._take_pending(max(0.0, deadline - self.clock.now()), until=len(sent) * 2 - len(buf))
            if len(buf) < 2 * len(sent):
                raise LineFault("stray", len(buf), "one copy of a write that may be an echo")
        self.echo = True
        return buf[len(sent) :]

    # ----- the line -----------------------------------------------------------------------------------------
    def _quiet(self, fault: LineFault, deadline: float) -> None:
        """Drop what is left of a failed try: a garbled or repeated reply is over once the line is quiet; after
        another request's reply or a disagreement, the real one may still come (until the deadline); after
        silence, a late reply (until the late-reply window has passed)."""
        data = fault.data
        if fault.kind in ("silent", "stray", "disagree"):
            until = deadline + (self.late_window if fault.kind == "silent" else 0.0)
            while (left := until - self.clock.now()) > 0:
                data += self._recv(left)
        if data := data + self._take_pending(max(self.settle, self.flush_gap)):
            self._stray(data)

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
            self._heard_at = self.clock.now()
            if self.trace:
                self.trace(False, data)
        return data


def _frame_length(head: bytes) -> int | None:
    """The length of the reply frame `head` starts (a read's, a write acknowledgement, an exception); None until
    three bytes are in, or for a function no reply of ours has."""
    if len(head) < 3:
        return None
    fc = head[1]
    if fc & 0x80:
        return 5
    if fc in (1, 2, 3, 4):
        return 5 + head[2]
    return 8 if fc in (WRITE_COIL, WRITE_ONE, WRITE_COILS, WRITE_MANY) else None


def _frames(data: bytes) -> list[bytes]:
    """The CRC-valid reply frames among stray bytes (a read's, a write acknowledgement, an exception)."""
    found, i = [], 0
    while i + 5 <= len(data):
        n = _frame_length(data[i:]) or 8
        if i + n <= len(data) and crc_ok(data[i : i + n]):
            found.append(data[i : i + n])
            i += n
        else:
            i += 1
    return found


def _said(answer: Answer) -> str:
    return f"exception {answer:02d}" if isinstance(answer, int) else str(answer)


def _fault(exc: NotAnswer, received: int, data: bytes) -> LineFault:
    return LineFault("garbled" if exc.garbled else "stray", received, str(exc), data)
