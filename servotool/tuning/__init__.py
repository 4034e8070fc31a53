"""Inertia identification and gain suggestions."""
