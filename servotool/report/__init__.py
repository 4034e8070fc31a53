"""Pictures of measurements: terminal charts (plotext), PNG charts (matplotlib, the optional `plot` extra) and the
tune report. Above the tuning layer (it draws tuning results), below commissioning (plan steps write reports)."""
