"""RTU has no transaction id: the link must prove a reply answers its request. A scripted line on virtual time
plays late, repeated and lost replies exactly where they hurt."""

from __future__ import annotations

from collections import deque

import pytest

from servotool.errors import DeviceError
from servotool.link.crc import with_crc
from servotool.link.exchange import Exchange

TIMEOUT = 0.1
REPLY_S = 0.001


class ScriptedLine:
    """A Wire to one drive (unit 1) on virtual time; each request is answered as the next script step says:
    ok, drop (acted on, no reply), lost (never reached the drive), dup (answered twice), late:S (answered S s
    after the request), copy:G (answered, and again G s later), held:N (answered just before the reply to the N-th
    request after it: later than any timeout). Addresses in `refuse` answer exception 02."""

    def __init__(
        self, regs: dict[int, int], script: list[str], then: str = "ok", refuse: frozenset[int] = frozenset()
    ) -> None:
        self.regs, self.script, self.then, self.refuse = dict(regs), deque(script), then, refuse
        self.now = 0.0
        self.sent: list[bytes] = []
        self._due: list[tuple[float, bytes]] = []
        self._held: list[list] = []  # [requests still to pass, frame]

    def writes(self) -> int:
        return sum(1 for f in self.sent if f[1] in (6, 16))

    def send(self, frame: bytes) -> None:
        self.sent.append(frame)
        step = self.script.popleft() if self.script else self.then
        for held in self._held:
            held[0] -= 1
        due = b"".join(f for n, f in self._held if n == 0)
        self._held = [h for h in self._held if h[0] > 0]
        if step == "lost":
            return
        reply = self._serve(frame)
        if step == "drop":
            return
        kind, _, arg = step.partition(":")
        if kind == "held":
            self._held.append([int(arg), reply])
            return
        delay = float(arg) if kind == "late" else REPLY_S
        if due:
            self._due.append((self.now + delay / 2, due))
        self._due.append((self.now + delay, reply))
        if kind in ("dup", "copy"):
            self._due.append((self.now + delay + (float(arg) if kind == "copy" else 0.0), reply))

    def inject(self, delay: float, data: bytes) -> None:
        """Bytes that arrive on the line `delay` s from now, whatever is asked."""
        self._due.append((self.now + delay, data))

    def recv(self, timeout: float) -> bytes:
        arrivals = [t for t, _ in self._due if t <= self.now + timeout]
        if not arrivals:
            self.now += timeout
            return b""
        self.now = max(self.now, min(arrivals))
        data = b"".join(b for t, b in self._due if t <= self.now)
        self._due = [(t, b) for t, b in self._due if t > self.now]
        return data

    def _serve(self, frame: bytes) -> bytes:
        fc, address = frame[1], int.from_bytes(frame[2:4], "big")
        if self.refuse & set(range(address, address + int.from_bytes(frame[4:6], "big"))):
            return with_crc(bytes([1, fc | 0x80, 2]))
        if fc == 3:
            count = int.from_bytes(frame[4:6], "big")
            data = b"".join(self.regs.get(a, 0).to_bytes(2, "big") for a in range(address, address + count))
            return with_crc(bytes([1, 3, len(data)]) + data)
        if fc == 6:
            self.regs[address] = int.from_bytes(frame[4:6], "big")
            return frame
        count = int.from_bytes(frame[4:6], "big")
        for i in range(count):
            self.regs[address + i] = int.from_bytes(frame[7 + 2 * i : 9 + 2 * i], "big")
        return with_crc(frame[:6])


class LineClock:
    """A scripted line's virtual time as the one Clock: sleeping moves it on."""

    def __init__(self, line: ScriptedLine | QueuedLine) -> None:
        self.line = line

    def now(self) -> float:
        return self.line.now

    def wall(self) -> float:
        return self.line.now

    def sleep(self, seconds: float) -> None:
        self.line.now += max(0.0, seconds)


def exchange(line: ScriptedLine, retries: int = 2) -> Exchange:
    return Exchange(line, timeout=TIMEOUT, retries=retries, clock=LineClock(line))


def test_a_late_reply_is_not_taken_for_the_answer_to_the_next_read():
    # The first read's reply comes after its timeout and its late window, while the second read is out; both
    # read one register and cannot widen, so only the ledger of owed replies tells them apart.
    line = ScriptedLine({10: 111, 20: 222}, ["late:0.3", "late:0.08"])
    ex = exchange(line, retries=0)
    with pytest.raises(DeviceError, match=r"no response within 0\.1 s after 1 try"):
        ex.read(1, 10, 1)
    ex.retries = 1
    assert ex.read(1, 20, 1) == [222]
    assert ex.read(1, 10, 1) == [111]


def test_a_monitors_repeated_read_takes_another_length_so_its_copies_cannot_answer_the_next():
    # A monitor reads 10 and 20 over and over. A copy of 10's reply stands in for its next read (the same registers,
    # read a moment ago), and the reply it displaced follows: the read of 20 after it is widened by the entry after
    # 20, so that reply has another length and is set aside.
    line = ScriptedLine({10: 111, 20: 222, 21: 7}, ["ok", "ok", "copy:0.0005"])
    ex = exchange(line)
    for _ in range(3):
        assert ex.read(1, 10, 1) == [111]
        assert ex.read(1, 20, 1, spare=(0, 1)) == [222]
    assert [f[4:6] for f in line.sent[:4]] == [b"\x00\x01", b"\x00\x01", b"\x00\x01", b"\x00\x02"]


def test_silence_alone_does_not_make_a_monitors_repeated_reads_confirmed():
    # A try nobody answers (a probe of an id that is silent by design, before a line speed's trial) leaves its reply
    # owed but shows nothing that repeats: the repeated reads after it alternate their widths and are used as they
    # come, one request each.
    line = ScriptedLine({10: 111, 20: 222, 21: 7}, ["lost"])
    ex = exchange(line, retries=0)
    with pytest.raises(DeviceError, match="no response"):
        ex.read(1, 10, 1)
    assert [ex.read(1, 20, 1, spare=(0, 1)) for _ in range(6)] == [[222]] * 6
    assert len(line.sent) == 1 + 6


def test_a_read_that_repeats_none_is_not_widened():
    line = ScriptedLine({10: 111, 20: 222, 21: 7}, [])
    ex = exchange(line)
    assert ex.read(1, 10, 1) == [111] and ex.read(1, 20, 1, spare=(0, 1)) == [222]  # a backup's reads
    assert [f[4:6] for f in line.sent] == [b"\x00\x01", b"\x00\x01"]


def test_a_copy_of_another_reads_reply_is_confirmed_not_used():
    # Same length, no room to widen: the copy repeats a reply heard for another request, so the read is confirmed.
    line = ScriptedLine({10: 111, 20: 222}, ["copy:0.0005"])
    ex = exchange(line)
    assert ex.read(1, 10, 1) == [111]
    assert ex.read(1, 20, 1) == [222]
    assert ex.read(1, 10, 1) == [111]


def test_a_reply_held_later_than_any_timeout_never_answers_another_read():
    # The first try's reply is held until just before the reply to the second request after it (the read of 20):
    # it is owed, so the read of 20 is confirmed, and its disagreeing confirmation is a fault.
    line = ScriptedLine({10: 111, 20: 222}, ["held:2"])
    ex = exchange(line, retries=2)
    assert ex.read(1, 10, 1) == [111]  # the first try silent, the second answered
    assert ex.read(1, 20, 1) == [222]
    assert ex.read(1, 10, 1) == [111]


def test_two_confirmations_that_disagree_are_a_fault():
    line = ScriptedLine({10: 111, 20: 222}, ["held:2"])
    ex = exchange(line, retries=1)
    assert ex.read(1, 10, 1) == [111]
    ex.retries = 0
    with pytest.raises(DeviceError, match=r"replies that disagree after \d tries \(\[111\], then \[222\]"):
        ex.read(1, 20, 1)


def test_a_widened_read_that_meets_an_exception_asks_for_its_registers_alone():
    line = ScriptedLine({10: 111, 20: 222}, [], refuse=frozenset({21}))
    ex = exchange(line)
    assert [ex.read(1, 20, 1, spare=(0, 1)) for _ in range(2)] == [[222], [222]]  # a monitor's
    assert ex.read(1, 20, 1, spare=(0, 1)) == [222]  # widened to 20..21 first: 21 is refused
    assert ex.read(1, 20, 1, spare=(0, 1)) == [222]  # and not widened again
    counts = [b"\x00\x01", b"\x00\x01", b"\x00\x02", b"\x00\x01", b"\x00\x01"]
    assert [f[4:6] for f in line.sent] == counts


def test_the_deadline_allows_for_the_frames_time_on_the_wire():
    # 16 registers at 2400 baud: the request and reply take 238 ms on the wire, beyond a 0.2 s timeout.
    char_s = 11 / 2400
    line = ScriptedLine({a: a for a in range(16)}, ["late:0.35", "lost"])
    ex = Exchange(line, timeout=0.2, retries=0, char_s=char_s, baud=2400, clock=LineClock(line))
    assert ex.read(1, 0, 16) == list(range(16))
    with pytest.raises(DeviceError, match=r"no response within 0\.2 s beyond the 238 ms the request and reply take"):
        ex.read(1, 0, 16)


def test_a_late_reply_within_the_late_window_is_flushed():
    line = ScriptedLine({10: 111, 20: 222}, ["late:0.15"])
    ex = exchange(line)
    assert ex.read(1, 10, 1) == [111]
    assert ex.read(1, 20, 1) == [222]
    assert ex.read(1, 10, 1) == [111]


def test_a_repeated_reply_is_not_taken_for_the_answer_to_the_next_read():
    line = ScriptedLine({10: 111, 20: 222}, ["dup", "dup", "ok", "dup"])
    ex = exchange(line)
    assert ex.read(1, 10, 1) == [111]
    assert ex.read(1, 20, 1) == [222]
    assert ex.read(1, 10, 1) == [111]


def test_a_write_whose_acknowledgement_is_lost_is_read_back_not_sent_again():
    line = ScriptedLine({30: 0}, ["drop"])
    exchange(line).write(1, 30, [5], multiple=False)
    assert line.regs[30] == 5 and line.writes() == 1


def test_a_write_the_drive_never_got_is_sent_again_after_the_read_back():
    line = ScriptedLine({30: 0, 31: 0}, ["lost"])
    exchange(line).write(1, 30, [5, 6])
    assert [line.regs[30], line.regs[31]] == [5, 6]
    assert line.writes() == 2


def test_a_trigger_whose_acknowledgement_is_lost_is_never_sent_again():
    line = ScriptedLine({40: 0}, ["drop"])
    with pytest.raises(DeviceError, match="may or may not have run; not sent again"):
        exchange(line).write(1, 40, [1], multiple=False, idempotent=False)
    assert line.writes() == 1


def test_an_acknowledgement_of_another_value_is_not_accepted():
    line = ScriptedLine({30: 0}, ["lost"])
    line.inject(0.01, with_crc(bytes([1, 6, 0, 30, 0, 7])))  # a stray acknowledgement of another write
    with pytest.raises(DeviceError, match="no reply that answers it after 1 try, last an acknowledgement of 7"):
        exchange(line, retries=0).write(1, 30, [9], multiple=False)


@pytest.mark.parametrize("op", ["read", "write"])
def test_tries_are_bounded(op):
    line = ScriptedLine({10: 1}, [], then="lost")
    ex = exchange(line, retries=2)
    with pytest.raises(DeviceError, match=r"no response within 0\.1 s after 3 tries"):
        ex.read(1, 10, 1) if op == "read" else ex.write(1, 10, [2])
    assert len(line.sent) == 3 and line.writes() == (1 if op == "write" else 0)  # a write, then read-backs


def test_an_echoing_adapter_is_recognised_and_its_echo_never_taken_for_a_reply():
    class EchoLine(ScriptedLine):
        def send(self, frame: bytes) -> None:
            self.inject(0.0, frame)
            super().send(frame)

    line = EchoLine({10: 111}, [])
    ex = Exchange(line, timeout=TIMEOUT, retries=0, echo=None, clock=LineClock(line))
    assert ex.read(1, 10, 1) == [111]
    ex.write(1, 10, [5], multiple=False)
    assert line.regs[10] == 5 and ex.echo is True
    line.script.append("lost")
    with pytest.raises(DeviceError, match="no response"):  # the echo alone is no acknowledgement
        ex.write(1, 10, [6], multiple=False)


def test_a_read_interrupted_while_its_reply_is_on_the_way_is_not_answered_by_that_reply():
    # Ctrl-C lands between a read's request and its reply (a motion command interrupted before it moves); the next
    # read, of another register, goes out before the stale reply arrives and comes back after it: only the link's
    # confirmation can tell them apart (issue 29: SDC's read-back took a stale 1 for PN95 and said the servo on).
    class InterruptedLine(ScriptedLine):
        def recv(self, timeout: float) -> bytes:
            if len(self.sent) == 1 and timeout > 0:  # waiting for the first reply
                raise KeyboardInterrupt
            return super().recv(timeout)

    line = InterruptedLine({10: 1, 20: 0}, ["late:0.01", "late:0.02"])
    ex = exchange(line)
    with pytest.raises(KeyboardInterrupt):
        ex.read(1, 10, 1)
    assert ex.read(1, 20, 1) == [0]


class QueuedLine:
    """A Wire whose n-th request gets the n-th scripted reply (b"" for none), on virtual time."""

    def __init__(self, replies: list[bytes]) -> None:
        self.replies, self.now, self.sent = deque(replies), 0.0, 0
        self._pending = b""

    def send(self, frame: bytes) -> None:
        self.sent += 1
        self._pending = self.replies.popleft() if self.replies else b""

    def recv(self, timeout: float) -> bytes:
        data, self._pending = self._pending, b""
        self.now += 0.001 if data else timeout
        return data


def test_after_a_fault_an_exception_reply_counts_only_when_repeated():
    from servotool.errors import ModbusException

    stale_02 = with_crc(bytes([1, 0x83, 2]))  # names no address: could answer any earlier read
    data = with_crc(bytes([1, 3, 2, 0, 42]))
    line = QueuedLine([b"", stale_02, data, data, data])  # the silent read owes a reply: data is confirmed too
    ex = Exchange(line, timeout=TIMEOUT, retries=0, clock=LineClock(line))
    with pytest.raises(DeviceError, match="no response"):
        ex.read(1, 0x10, 1)  # silent: its reply may still come
    ex.retries = 1
    assert ex.read(1, 0x20, 1) == [42]  # the exception that came first was not believed
    line = QueuedLine([stale_02, stale_02])
    ex = Exchange(line, timeout=TIMEOUT, retries=0, clock=LineClock(line))
    with pytest.raises(ModbusException):
        ex.read(1, 0x20, 1)  # a clean line: believed at once
    assert line.sent == 1
