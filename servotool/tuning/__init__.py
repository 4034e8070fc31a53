"""Tuning in three rooms: the procedures that move a drive to identify its load and set its gains (this package:
preflight, planning, identify with sampling and band_guard, stable_hold, step, gain_writes, gain_search, tune),
over two pure ones that never touch a drive, fit/ (a log in, the inertia estimate out) and control/ (gains, margins
and friction compensation from a plant)."""
