"""Allow `python -m servotool`."""

from servotool.cli.main import run

run()
