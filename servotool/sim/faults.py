"""A bad RS485 line for the simulator: a proxy between a master and the served drives (RTU over TCP) that damages
replies, seeded and reproducible.

Each reply frame gets at most one fault, drawn with a seeded random.Random: a CRC error, dropped, late by a given
delay (while later replies pass), sent twice, truncated, or replaced by garbage. Every reply can also be delayed
(a slow drive), and the master's own transmission can be echoed back to it (an RS485 adapter with local echo).
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from dataclasses import dataclass, field

from servotool.errors import UsageError

KINDS = ("crc", "drop", "late", "duplicate", "truncate", "garbage")


@dataclass(frozen=True)
class LineFaults:
    """What the line does to replies: probability per reply frame of each fault kind, and the line's habits."""

    rates: dict[str, float] = field(default_factory=dict)
    seed: int = 1
    late_s: float = 0.5  # how much later than its time a "late" reply comes
    response_delay_s: float = 0.0  # the drive's reply delay, on every reply
    echo: bool = False  # the master hears its own transmission

    def __post_init__(self) -> None:
        for kind, rate in self.rates.items():
            if kind not in KINDS:
                raise UsageError(f"unknown line fault '{kind}' (one of: {', '.join(KINDS)}, mixed)")
            if not 0.0 <= rate <= 1.0:
                raise UsageError(f"line fault {kind}: rate {rate:g} is not between 0 and 1")
        if sum(self.rates.values()) > 1.0:
            raise UsageError("line fault rates add up to more than 100 %")
        if self.late_s < 0 or self.response_delay_s < 0:
            raise UsageError("line delays must be >= 0")


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


def reply_length(buf: bytes) -> int | None:
    """Length of the RTU reply frame at the start of buf (None: not known yet, or not a reply this line knows)."""
    if len(buf) < 3:
        return None
    fc = buf[1]
    if fc & 0x80:
        return 5
    if fc in (3, 4):
        return 5 + buf[2]
    if fc in (5, 6, 15, 16):
        return 8
    return len(buf)


class FaultProxy:
    """Listens on host:port and relays to the drives' RTU-over-TCP port, damaging replies as `faults` says."""

    def __init__(self, upstream: tuple[str, int], faults: LineFaults) -> None:
        self.upstream = upstream
        self.applied: dict[str, int] = {}
        self.set_faults(faults)
        self._server: asyncio.Server | None = None

    def set_faults(self, faults: LineFaults) -> None:
        """Change what the line does (and restart its random sequence from the seed)."""
        self.faults, self._rng = faults, random.Random(faults.seed)

    async def start(self, host: str = "127.0.0.1", port: int = 0) -> int:
        """Start listening; the bound port."""
        self._server = await asyncio.start_server(self._serve, host, port)
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 2)
            self._server = None

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.upstream)
        except OSError:
            writer.close()
            return
        replies = asyncio.ensure_future(self._replies(up_reader, writer))
        try:
            while data := await reader.read(4096):
                if self.faults.echo:
                    writer.write(data)
                up_writer.write(data)
        except (OSError, asyncio.CancelledError):
            pass
        finally:
            replies.cancel()
            up_writer.close()
            writer.close()

    async def _replies(self, up_reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        buf = b""
        loop = asyncio.get_running_loop()
        while data := await up_reader.read(4096):
            buf += data
            while (n := reply_length(buf)) is not None and len(buf) >= n:
                frame, buf = buf[:n], buf[n:]
                delay, out = self._damage(frame)
                delay += self.faults.response_delay_s
                if not out:
                    continue
                if delay > 0:
                    loop.call_later(delay, _send, writer, out)
                else:
                    _send(writer, out)

    def _damage(self, frame: bytes) -> tuple[float, bytes]:
        """(extra delay, bytes to send) for one reply frame, after at most one fault."""
        kind = self._pick()
        if kind is None:
            return 0.0, frame
        self.applied[kind] = self.applied.get(kind, 0) + 1
        rng = self._rng
        if kind == "crc":
            i = rng.randrange(len(frame))
            return 0.0, frame[:i] + bytes([frame[i] ^ (1 << rng.randrange(8))]) + frame[i + 1 :]
        if kind == "late":
            return self.faults.late_s, frame
        if kind == "duplicate":
            return 0.0, frame + frame
        if kind == "truncate":
            return 0.0, frame[: rng.randrange(1, len(frame))]
        if kind == "garbage":
            return 0.0, rng.randbytes(rng.randrange(1, len(frame) + 4))
        return 0.0, b""  # drop

    def _pick(self) -> str | None:
        x = self._rng.random()
        for kind in KINDS:
            x -= self.faults.rates.get(kind, 0.0)
            if x < 0:
                return kind
        return None


def _send(writer: asyncio.StreamWriter, data: bytes) -> None:
    if not writer.is_closing():
        writer.write(data)
