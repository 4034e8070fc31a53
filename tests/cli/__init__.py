"""Tests of the command line (servotool.cli)."""
