"""Learning curves and measuring time of a campaign: the forecast a plan makes before anything moves, the curve a
run measured, and the minutes against the full grid's.

``plan_learning``: what ``campaign plan`` prints (``campaign.plan.learning.forecast_curve``, the plan's and the full
grid's predicted minutes). ``forecast_event``: the same, logged when a run starts (``forecast`` event). With it,
``learning_summary`` gives ``report.json``'s ``learning`` of an optimal or adaptive run: the forecast, the held-out
RMS measured after the first 25, 50, 100... calibration points (in measurement order: the order they were chosen;
each prefix refitted by the default process, judged on the run's test set) and the measuring time: the sequence
measured timed like a plan (motion at the caps, settling, readings: ``campaign.run.eta``), comparable with the plan's
and the full grid's, and the robot time the log's clock recorded.
"""
from __future__ import annotations

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset
from campaign.errors import DataError
from campaign.plan.learning import SIZES, forecast_curve
from campaign.plan.points import Plan, PlanPoint
from campaign.run.log_events import ForecastEvent
from campaign.run.log_records import PointRecord
from campaign.run.eta import budget_duration_s, estimate_duration_s, grid_duration_s

from .report_sections import LearningCurve
from .stages import calibrate_dataset

FORECAST_EVENT = ForecastEvent.TYPE
MEASURED_SIZES = tuple(s for s in SIZES if s >= 25)


def plan_learning(cell: CellModel, plan: Plan) -> tuple[tuple[tuple[int, float], ...], dict]:
    """(forecast curve, minutes: ``plan``, ``budget`` (adaptive plans: the whole pose budget) and ``grid``)."""
    kind = cell.config.plan.kind
    minutes = {"plan": estimate_duration_s(plan.points, cell) / 60.0,
               "budget": budget_duration_s(plan.points, cell) / 60.0 if kind == "adaptive" else None,
               "grid": grid_duration_s(cell) / 60.0 if kind in ("optimal", "adaptive") else None}
    return forecast_curve(cell, plan), minutes


def forecast_event(cell: CellModel, plan: Plan) -> ForecastEvent:
    """The ``forecast`` log event of a run that starts now."""
    curve, minutes = plan_learning(cell, plan)
    return ForecastEvent([list(c) for c in curve],
                         minutes["budget"] if minutes["budget"] is not None else minutes["plan"], minutes["grid"])


def measured_curve(ds: Dataset, cell: CellModel, sizes=MEASURED_SIZES, *,
                   force: bool = False) -> tuple[tuple[int, float], ...]:
    """((n, held-out RMS mm), ...): the first n calibration rows of ``ds`` (measurement order) with every other row,
    calibrated by the default process, for n in ``sizes`` below the number of calibration rows (not the last:
    that is the report itself)."""
    cal = np.flatnonzero(ds.mask("calib"))
    if not ds.mask("test").any():
        return ()
    ordered = ds.with_order_context()
    out = []
    for n in (s for s in sizes if s < len(cal)):
        keep = ~ds.mask("calib")
        keep[cal[:n]] = True
        try:
            rms = calibrate_dataset(ordered.subset(keep), cell, force=force).report.final.test.rms_mm
        except DataError:                                  # too few rows for a plausible fit: no point on the curve
            continue
        if rms is not None:
            out.append((int(n), float(rms)))
    return tuple(out)


def learning_summary(ds: Dataset, cell: CellModel, contents, final_rms_mm: float | None, *,
                     force: bool = False) -> LearningCurve | None:
    """``report.json``'s ``learning`` of a run whose log holds a ``forecast`` event (optimal and adaptive runs);
    ``final_rms_mm`` the report's own held-out RMS, the measured curve's last point (all calibration points)."""
    event = next((e for e in (getattr(contents, "events", None) or []) if e.get("type") == FORECAST_EVENT), None)
    if event is None:
        return None
    records = contents.records()
    logged = sum(max(0.0, float(r.t_end_s - r.t_start_s)) for r in records) / 60.0
    measured = measured_curve(ds, cell, force=force)
    if final_rms_mm is not None:
        measured += ((int(ds.mask("calib").sum()), float(final_rms_mm)),)
    return LearningCurve(tuple((int(n), float(v)) for n, v in event.get("curve", ())), measured,
                         estimate_duration_s(measured_sequence(records), cell) / 60.0, event.get("minutes_planned"),
                         event.get("minutes_grid"), logged)


def measured_sequence(records) -> list[PlanPoint]:
    """The points a run measured, in order, as plan points (a nest reading where the robot stood): what
    ``campaign.run.eta`` times like a plan, so that the run's minutes compare with the plan's and the grid's."""
    out, q = [], None
    for r in records:
        if isinstance(r, PointRecord):
            q = tuple(r.q_cmd_deg)
            out.append(PlanPoint(r.point_id, r.set, q, tuple(r.p_target_base_mm or (0.0, 0.0, 0.0))))
        elif q is not None:
            out.append(PlanPoint(r.point_id, "nest", q, (0.0, 0.0, 0.0)))
    return out
