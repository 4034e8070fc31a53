"""Loop gains, pure: each drive's rigidity levels, the gains for a plant and a level, and their margins. It imports
numpy, the standard library and servotool.model only (tests/test_layers.py holds it)."""
