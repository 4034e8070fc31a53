"""Tests of servotool.ops."""
