"""Command-line interface: parse, call the library, render."""

from servotool.cli.classcache import install

install()  # before the modules of a command define their dataclasses
