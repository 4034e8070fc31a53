"""Port specs and line settings, and the Link protocol drive operations use. No pymodbus here: the simulator
imports this module and must stand without the client."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from servotool.errors import UsageError
from servotool.model.profile import LineSettings

Trace = Callable[[bool, bytes], None]


@dataclass(frozen=True)
class LinkSettings:
    """Where and how to talk to a drive."""

    port: str
    line: LineSettings = field(default_factory=LineSettings)
    timeout: float = 1.0
    retries: int = 2
    echo: bool | None = False     # the adapter echoes what it sends (None: find out from the first replies)


class Link(Protocol):
    """What drive operations need from a Modbus master."""

    def read(self, unit: int, address: int, count: int) -> list[int]: ...
    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True,
              idempotent: bool = True) -> None:
        """Write registers. idempotent=False (an Fn trigger) means a write whose fate is unknown is never sent
        again; an idempotent one may be."""
        ...
    def close(self) -> None: ...


_TCP_RE = re.compile(r"^tcp://(?P<host>\[[^\]]+\]|[^:/]+):(?P<port>\d+)$")


def parse_tcp(port: str) -> tuple[str, int] | None:
    """(host, port) of a tcp://host:port spec, None for other specs; UsageError when malformed."""
    if not port.startswith("tcp://"):
        return None
    m = _TCP_RE.match(port)
    if not m or not 0 <= int(m["port"]) < 65536:
        raise UsageError(f"bad port '{port}': expected tcp://HOST:PORT")
    return m["host"].strip("[]"), int(m["port"])
