# MIT License (see the servotool repository)
"""servotool.drives.connection: the connection options every module of the collection takes (one description)."""

from __future__ import annotations


class ModuleDocFragment:
    DOCUMENTATION = r"""
options:
  port:
    description: Serial port (C(/dev/ttyUSB0), C(COM3)), C(tcp://HOST:PORT) (RTU over TCP) or C(sim).
    type: str
    required: true
  profile:
    description: Drive profile id (C(sd25), C(is620p), C(sdc), C(dsx7e)); found from the drive's answers when left out.
    type: str
  unit:
    description: Modbus unit id 1..247 (default the profile's).
    type: int
  baud:
    description: Baud rate (default the profile's factory setting).
    type: int
  parity:
    description: Parity (default the profile's).
    type: str
    choices: [N, E, O]
  stopbits:
    description: Stop bits (default the profile's).
    type: int
    choices: [1, 2]
  timeout:
    description: Seconds to wait for each answer.
    type: float
  retries:
    description: Tries after a timeout.
    type: int
"""
