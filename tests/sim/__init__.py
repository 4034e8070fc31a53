"""Tests of servotool.sim (a package, so its conftest does not shadow tests/conftest.py)."""
