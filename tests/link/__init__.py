"""Tests of servotool.link."""
