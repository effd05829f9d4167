"""How a quantity is printed, one owner each: the noise floor has one format in every output (terminal, HTML,
figures), so one floor never shows as 0.032, 0.0320 and 0.033 mm."""
from __future__ import annotations

FLOOR_FMT = ".3f"
"""The noise floor, mm (1 µm; the floor's own uncertainty from a few dozen repeats is several µm)."""


def floor_mm(value: float | None) -> str:
    """The noise floor as printed everywhere, without the unit ("0.028"); "-" for None."""
    return "-" if value is None else format(value, FLOOR_FMT)


CONDITION_SCALE = ((100.0, "good"), (10_000.0, "fair"), (float("inf"), "poor"))
"""The condition number of the column-scaled identification Jacobian, in words: up to 100 every identified
parameter is well determined; up to 10 000 some combinations are weakly determined (their sigma tells); above,
some combinations are barely determined by the poses (a larger or better-spread pose set, or fewer parameters)."""


def condition_scale(value: float | None) -> str:
    """"good", "fair" or "poor" on :data:`CONDITION_SCALE` ("-" for None)."""
    if value is None:
        return "-"
    return next(word for bound, word in CONDITION_SCALE if value <= bound)


def condition_meaning(n_parameters: int, forecast: bool) -> str:
    """What a condition number is of, in one line: ``campaign plan``'s forecast (``forecast``) and a calibration
    report print the same quantity, the column-scaled Jacobian of the geometric parameters identified, at two
    places (the nominal geometry on the planned poses; the identified geometry on the measured points)."""
    if forecast:
        return (f"of the {n_parameters} identifiable geometric parameters at the nominal geometry on the plan's "
                "calibration poses; the run reports the same quantity at the identified geometry on the measured "
                "points")
    return (f"of the {n_parameters} identified geometric parameters at the identified geometry on the measured points; "
            "campaign plan forecasts the same quantity at the nominal geometry on the planned poses")
