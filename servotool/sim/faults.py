"""A bad RS485 line for the simulator: a proxy between a master and the served drives (RTU over TCP) that does to
frames what real lines, adapters, gateways and drives do, seeded and reproducible.

Each reply frame gets at most one fault, drawn with a seeded random.Random: a CRC error (crc), lost (drop), late by
a given delay while later replies pass (late), held back until just before the reply to a request 1-8 requests
later, so later than any timeout (stale), sent again after a gap of 0 to `gap_s` (duplicate: a gateway or a drive
that retries), answered from another unit id (unit), truncated, or replaced by garbage; a burst makes the next 2-6
replies faulty in a row. Each request may also come back to the master after such a gap (echo: a converter that
reflects it). The line's habits: every reply delayed (a slow drive), every request echoed at once (an RS485 adapter
with local echo), and writes to given addresses acknowledged but ignored (a drive that answers a write it does not
make: the proxy answers it itself and forwards nothing, so the drive keeps its old value and reads say so).
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from dataclasses import dataclass, field

from servotool.errors import UsageError
from servotool.link.crc import with_crc
from servotool.model.profile import Profile

REPLY_KINDS = ("crc", "drop", "late", "stale", "duplicate", "unit", "truncate", "garbage", "burst")
KINDS = (*REPLY_KINDS, "echo")
STALE_AFTER = (1, 8)  # a stale reply comes just before the reply to the request this many requests later
BURST = (2, 6)  # replies in a row a burst damages
WRITE_CODES = (5, 6, 15, 16)


@dataclass(frozen=True)
class LineFaults:
    """What the line does to frames: probability per reply frame of each fault kind (echo: per request), and the
    line's habits."""

    rates: dict[str, float] = field(default_factory=dict)
    seed: int = 1
    late_s: float = 0.5  # how much later than its time a "late" reply comes
    gap_s: float = 0.05  # the longest gap before a duplicate or an echo (drawn from 0..gap_s)
    response_delay_s: float = 0.0  # the drive's reply delay, on every reply
    echo: bool = False  # the master hears its own transmission, at once
    ignore_writes: frozenset[int] = frozenset()  # register addresses whose writes are acknowledged but not made

    def __post_init__(self) -> None:
        for kind, rate in self.rates.items():
            if kind not in KINDS:
                raise UsageError(f"unknown line fault '{kind}' (one of: {', '.join(KINDS)}, mixed)")
            if not 0.0 <= rate <= 1.0:
                raise UsageError(f"line fault {kind}: rate {rate:g} is not between 0 and 1")
        if sum(self.rates.values()) > 1.0:
            raise UsageError("line fault rates add up to more than 100 %")
        if self.late_s < 0 or self.response_delay_s < 0 or self.gap_s < 0:
            raise UsageError("line delays must be >= 0")
        for address in self.ignore_writes:
            if not 0 <= address <= 0xFFFF:
                raise UsageError(f"register address {address} is not 0..65535")


def parse_rates(text: str) -> dict[str, float]:
    """'crc:5%,late:0.01' -> {"crc": 0.05, "late": 0.01}; 'mixed:R' spreads R evenly over every kind."""
    rates: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        kind, sep, value = item.partition(":")
        try:
            rate = float(value.rstrip("%")) / (100.0 if value.endswith("%") else 1.0)
        except ValueError:
            rate = -1.0
        if not sep or rate < 0:
            raise UsageError(f"bad line fault '{item}': expected KIND:RATE (RATE as 0.05 or 5%)")
        spread = {k: rate / len(KINDS) for k in KINDS} if kind == "mixed" else {kind: rate}
        for k, r in spread.items():
            rates[k] = rates.get(k, 0.0) + r
    return rates


def parse_addresses(profile: Profile, text: str) -> frozenset[int]:
    """'Po505,0x2004' -> the register addresses of those entries (all of a multi-register one) and numbers."""
    addresses: set[int] = set()
    for item in filter(None, (part.strip() for part in text.split(","))):
        try:
            addresses.add(int(item, 0))
            continue
        except ValueError:
            pass
        addresses.update(profile.entry(item).addresses)  # UnknownName (a usage error) when it is neither
    return frozenset(addresses)


def reply_length(buf: bytes) -> int | None:
    """Length of the RTU reply frame at the start of buf (None: not known yet, or not a reply this line knows)."""
    if len(buf) < 3:
        return None
    fc = buf[1]
    if fc & 0x80:
        return 5
    if fc in (3, 4):
        return 5 + buf[2]
    if fc in WRITE_CODES:
        return 8
    return len(buf)


def request_length(buf: bytes) -> int | None:
    """Length of the RTU request frame at the start of buf (None: not known yet); the whole of buf for a function
    this line does not parse."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in (1, 2, 3, 4, 5, 6):
        return 8
    if fc in (15, 16):
        return 9 + buf[6] if len(buf) >= 7 else None
    return len(buf)


class FaultProxy:
    """Listens on host:port and relays to the drives' RTU-over-TCP port, damaging frames as `faults` says."""

    def __init__(self, upstream: tuple[str, int], faults: LineFaults) -> None:
        self.upstream = upstream
        self.applied: dict[str, int] = {}
        self.set_faults(faults)
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    def set_faults(self, faults: LineFaults) -> None:
        """Change what the line does (and restart its random sequences from the seed)."""
        self.faults = faults
        self.rng = random.Random(faults.seed)  # reply faults
        self._request_rng = random.Random(faults.seed + 0x5EED)  # echoes: their own sequence, so replies keep theirs
        self._burst = 0

    async def start(self, host: str = "127.0.0.1", port: int = 0) -> int:
        """Start listening; the bound port."""
        self._server = await asyncio.start_server(self._serve, host, port)
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        """Stop listening and end every connection (their tasks finish here, not when the loop is gone)."""
        if self._server is not None:
            self._server.close()
            for task in list(self._tasks):
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 2)
            self._server = None

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        try:
            await self._relay(reader, writer)
        finally:
            self._tasks.discard(task)

    async def _relay(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        except OSError:
            writer.close()
            return
        line = _Connection(self, writer)
        replies = asyncio.ensure_future(line.replies(up_reader))
        buf = b""
        try:
            while data := await reader.read(4096):
                if self.faults.echo:
                    writer.write(data)
                buf += data
                while (n := request_length(buf)) is not None and len(buf) >= n:
                    frame, buf = buf[:n], buf[n:]
                    if not line.request(frame):
                        up_writer.write(frame)
        except (OSError, asyncio.CancelledError):
            pass
        finally:
            replies.cancel()
            await asyncio.gather(replies, return_exceptions=True)
            up_writer.close()
            writer.close()

    def count(self, kind: str) -> None:
        self.applied[kind] = self.applied.get(kind, 0) + 1

    def pick(self) -> str | None:
        """The fault of the next reply frame (None: it passes), bursts included."""
        rates = {k: r for k, r in self.faults.rates.items() if k in REPLY_KINDS}
        if self._burst > 0:
            self._burst -= 1
            kinds = [k for k in rates if k != "burst"] or [k for k in REPLY_KINDS if k != "burst"]
            return self.rng.choice(kinds)
        x = self.rng.random()
        for kind in REPLY_KINDS:
            x -= rates.get(kind, 0.0)
            if x < 0:
                if kind == "burst":
                    self.count(kind)
                    self._burst = self.rng.randint(*BURST)
                    return self.pick()
                return kind
        return None

    def echo_gap(self) -> float | None:
        """The gap after which a request comes back to the master (None: it does not)."""
        rate = self.faults.rates.get("echo", 0.0)
        if rate and self._request_rng.random() < rate:
            self.count("echo")
            return self._request_rng.uniform(0.0, self.faults.gap_s)
        return None


class _Connection:
    """One master's connection through the proxy: its requests on the way up, its replies on the way down."""

    def __init__(self, proxy: FaultProxy, writer: asyncio.StreamWriter) -> None:
        self.proxy, self.writer = proxy, writer
        self._held: list[tuple[int, bytes]] = []  # stale replies: (replies still to pass before it goes, frame)
        self._loop = asyncio.get_running_loop()

    def request(self, frame: bytes) -> bool:
        """Handle one request frame from the master; True when the proxy answered it itself (not forwarded)."""
        if (gap := self.proxy.echo_gap()) is not None:
            self._later(gap, frame)
        if not (ack := self._ignored(frame)):
            return False
        self.proxy.count("ignored write")
        self.reply(ack)
        return True

    def _ignored(self, frame: bytes) -> bytes:
        """The acknowledgement a drive would send for a write it ignores (b"" when it makes this one)."""
        ignored = self.proxy.faults.ignore_writes
        if not ignored or len(frame) < 8 or frame[1] not in WRITE_CODES or frame[0] == 0:
            return b""
        address = int.from_bytes(frame[2:4], "big")
        count = int.from_bytes(frame[4:6], "big") if frame[1] in (15, 16) else 1
        if frame[1] in (5, 15) or not any(a in ignored for a in range(address, address + count)):
            return b""
        return frame[:8] if frame[1] == 6 else with_crc(frame[:6])

    async def replies(self, up_reader: asyncio.StreamReader) -> None:
        buf = b""
        while data := await up_reader.read(4096):
            buf += data
            while (n := reply_length(buf)) is not None and len(buf) >= n:
                frame, buf = buf[:n], buf[n:]
                self.reply(frame)

    def reply(self, frame: bytes) -> None:
        """Pass one reply frame to the master after at most one fault; stale ones held back go just before it."""
        due = [f for left, f in self._held if left <= 1]
        self._held = [(left - 1, f) for left, f in self._held if left > 1]
        kind = self.proxy.pick()
        if kind is not None:
            self.proxy.count(kind)
        delay, out, copy_after = self._damage(kind, frame)
        out = b"".join(due) + out
        delay += self.proxy.faults.response_delay_s
        if out:
            self._later(delay, out)
        if copy_after is not None:
            self._later(delay + copy_after, frame)

    def _damage(self, kind: str | None, frame: bytes) -> tuple[float, bytes, float | None]:
        """(extra delay, bytes to send, gap before a copy of the frame follows or None) for one reply frame."""
        rng = self.proxy.rng
        if kind is None:
            return 0.0, frame, None
        if kind == "crc":
            i = rng.randrange(len(frame))
            return 0.0, frame[:i] + bytes([frame[i] ^ (1 << rng.randrange(8))]) + frame[i + 1 :], None
        if kind == "late":
            return self.proxy.faults.late_s, frame, None
        if kind == "stale":
            self._held.append((rng.randint(*STALE_AFTER), frame))
            return 0.0, b"", None
        if kind == "duplicate":
            return 0.0, frame, rng.uniform(0.0, self.proxy.faults.gap_s)
        if kind == "unit":
            other = frame[0] % 247 + 1
            return 0.0, with_crc(bytes([other]) + frame[1:-2]), None
        if kind == "truncate":
            return 0.0, frame[: rng.randrange(1, len(frame))], None
        if kind == "garbage":
            return 0.0, rng.randbytes(rng.randrange(1, len(frame) + 4)), None
        return 0.0, b"", None  # drop

    def _later(self, delay: float, data: bytes) -> None:
        if delay > 0:
            self._loop.call_later(delay, self._send, data)
        else:
            self._send(data)

    def _send(self, data: bytes) -> None:
        if not self.writer.is_closing():
            self.writer.write(data)
