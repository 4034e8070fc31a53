"""The one way JSON gives a value with a unit: {"value": 300.0, "unit": "rpm"} (issue 33: not also a `units` map
beside the values, nor the unit in the key's name as in `speed_rpm`)."""

from __future__ import annotations

from typing import Any


def quantity(value: float | int | None, unit: str, **more: Any) -> dict[str, Any] | None:
    """A number with its unit (and any more fields, such as its standard deviation `std`); None stays None, so an
    unknown value reads as null, not as an object without a value."""
    if value is None:
        return None
    return {"value": value, "unit": unit, **more}
