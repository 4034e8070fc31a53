"""The playbook's independent reader (tests/ansible/playbook.yml): holding registers of a `sim serve` drive, read by
pymodbus' own client (tests/frames.plain_read), not by servotool, printed as JSON {address: value}.

Usage: python read_registers.py tcp://HOST:PORT UNIT ADDRESS..."""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script by the play: the checkout's tests

from tests.frames import plain_read


def main() -> None:
    port, unit, addresses = sys.argv[1], int(sys.argv[2]), [int(a) for a in sys.argv[3:]]
    print(json.dumps({str(a): plain_read(port, a, 1, unit=unit)[0] for a in addresses}))


if __name__ == "__main__":
    main()
