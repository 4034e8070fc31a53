"""Tests of servotool.model."""
