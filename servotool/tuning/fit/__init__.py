"""The inertia fit, pure: a logged motion in, an estimate with its uncertainty and notes out. It imports numpy, the
standard library and servotool.model only (tests/test_layers.py holds it), so it runs on any log, live or saved."""
