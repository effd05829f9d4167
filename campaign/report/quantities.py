"""How a quantity is printed, one owner each: the noise floor has one format in every output (terminal, HTML,
figures), so one floor never shows as 0.032, 0.0320 and 0.033 mm."""
from __future__ import annotations

FLOOR_FMT = ".3f"
"""The noise floor, mm (1 µm; the floor's own uncertainty from a few dozen repeats is several µm)."""


def floor_mm(value: float | None) -> str:
    """The noise floor as printed everywhere, without the unit ("0.028"); "-" for None."""
    return "-" if value is None else format(value, FLOOR_FMT)
