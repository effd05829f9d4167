"""``report.json`` as a typed record: ``CalibrationReport`` (built by ``campaign.calibrate.stages``), and the
calibration stages it reports (:data:`STAGES`, the one owner of their names and labels)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

from campaign.io.json_fields import (RecordError, get_field, json_value, list_field, number_field, object_field,
                                     record_field, record_map_field, records_field, text_field)
from robocal.diagnose.budget import ErrorBudget
from robocal.identify.identification import Unidentifiable

from .plausibility import Plausibility
from .summary import Summary
from .report_sections import (EffectsReport, ExcludedPoint, MethodChoice, MultiSmrReport, ParameterRow,
                              ResidualChoice, ResidualCV, RowCounts, StageResult, StopSummary, LearningCurve,
                              unidentifiable_from_dict)


@dataclass(frozen=True)
class Stage:
    """A calibration stage: its key in ``report.json``'s ``stages``, its table label, its short (figure) name."""
    name: str
    label: str
    short: str


NOMINAL, KINEMATIC, ELASTIC, COMPENSATED = "nominal", "kinematic", "elastic", "compensated"
STAGES = (Stage(NOMINAL, "nominal (uncompensated)", "nominal"),
          Stage(KINEMATIC, "kinematic calibration", "kinematic"),
          Stage(ELASTIC, "kinematic + physical effects", "elastic"),
          Stage(COMPENSATED, "final model (+ residual layer, if any)", "final model"))
"""Seed 000 Table 3's stages in report order (``elastic`` only when physical effects were taken)."""

IDENTIFICATION_KEYS = ("robot_identity", "tracker_identity", "driver_versions", "software_version", "identity_check",
                       "config_sha256", "plan_sha256", "started_utc", "finished_utc", "measuring_s",
                       "simulated_devices", "provenance")
_N_REPORT_KEYS = 26                                       # the always-present report.json keys, before multi_smr


@dataclass(frozen=True, eq=False)
class CalibrationReport:
    """``report.json``: the calibration's figures (see ``campaign.calibrate.stages.calibrate_dataset``).

    ``n`` row counts (calib/test/check/rejected); ``stages`` per-stage error statistics on the test and calib rows
    (mm, keyed by :data:`STAGES` names); ``noise_floor_mm`` with its source ("repeats" or "specs") and both
    candidates; the identified ``parameters`` (the rows of model.json's parameter record, from the fit named by
    ``parameters_fit``, whose unit-weight error is ``parameters_sigma0``; ``parameters_geometry_only``: the geometric fit's, when the exported model also has
    physical effects) and their diagnostics; ``T_tracker_base`` (4, 4) registration (mm);
    the method and effect choices; ``preparation`` (the JSON section of ``campaign.calibrate.prepare``); optional
    ``multi_smr``; ``stop`` (``plan.stop: auto`` runs: every refit's predicted held-out RMS curve and decision,
    with the held-out RMS measured at the end); ``cell`` summary and per-point ``points`` table (JSON of
    ``report_points``, for the HTML figures); the hardware ``identification`` of the run log (robot/tracker
    identity, driver and software versions, config and plan hashes, start and end, simulated devices) when
    processed from a log; the ``summary`` (verdict, one-line model: ``campaign.calibrate.summary``) of a report
    a command wrote; the error ``budget`` on the test rows (``campaign.calibrate.budget_stage``).
    """

    format: str
    config: str
    source: str
    n: RowCounts
    stages: dict[str, StageResult]
    noise_floor_mm: float
    noise_floor_source: str
    noise_floor_specs_mm: float
    noise_floor_repeats_mm: float | None
    parameters: tuple[ParameterRow, ...]
    unidentifiable: tuple[Unidentifiable, ...]
    condition_number: float
    observability: Any
    sigma0: float
    iterations: int
    converged: bool
    rejected_points: tuple[str, ...]
    excluded_points: tuple[ExcludedPoint, ...]
    structure_note: str | None
    T_tracker_base: list
    method: MethodChoice | None
    effects: EffectsReport | None
    residual_choice: ResidualChoice | None
    plausibility: Plausibility | None
    residual_cv: ResidualCV | None
    preparation: dict | None
    multi_smr: MultiSmrReport | None = None
    stop: StopSummary | None = None
    cell: Any = None
    points: Any = None
    identification: tuple[tuple[str, Any], ...] = ()
    summary: Summary | None = None
    parameters_fit: str | None = None
    parameters_geometry_only: tuple[ParameterRow, ...] | None = None
    parameters_sigma0: float | None = None          # the unit-weight error of the fit the parameters come from
    budget: ErrorBudget | None = None
    learning: LearningCurve | None = None      # optimal and adaptive runs: forecast and measured learning curves

    @property
    def final(self) -> StageResult | None:
        """The final model's stage (``compensated``)."""
        return self.stages.get(COMPENSATED)

    def to_dict(self) -> dict:
        """The report.json object (the key order written so far)."""
        out = {}
        for name in REPORT_KEYS:
            out[name] = json_value(getattr(self, name))
            if name == "parameters":                 # the fit the rows come from, the geometry-only rows beside
                out.update((k, json_value(getattr(self, k))) for k in PARAMETER_KEYS if getattr(self, k) is not None)
        if self.multi_smr is not None:
            out["multi_smr"] = self.multi_smr.to_dict()
        if self.stop is not None:
            out["stop"] = self.stop.to_dict()
        if self.learning is not None:
            out["learning"] = self.learning.to_dict()
        out["cell"], out["points"] = self.cell, self.points
        out.update(self.identification)
        if self.summary is not None:
            out["summary"] = self.summary.to_dict()
        if self.budget is not None:
            out["budget"] = self.budget.to_dict()
        return out

    def with_identification(self, ident: Mapping) -> "CalibrationReport":
        """A copy carrying the run log's hardware identification (``robot_identity``... ``software_version``)."""
        return replace(self, identification=tuple((k, ident[k]) for k in IDENTIFICATION_KEYS if k in ident))

    def without_devices(self, provenance: str) -> "CalibrationReport":
        """A copy for data that record no device (an interchange CSV): ``provenance`` says where they came from, and
        the cell summary keeps the config's robot and tracker models but not its driver URLs (None: the config's
        devices, not the data's)."""
        cell = self.cell if not isinstance(self.cell, Mapping) else {**self.cell, "robot_url": None,
                                                                         "tracker_url": None}
        return replace(self, identification=(("provenance", provenance),), cell=cell)

    @classmethod
    def from_dict(cls, data: Mapping) -> "CalibrationReport":
        """A report.json object; RecordError names a missing field or one of the wrong kind (by its path below the
        report, ``stages.kinematic.test.rms_mm``). Sections a report of an earlier version lacks read as None."""
        if not isinstance(data, Mapping):
            raise RecordError("report", f"expected an object, got {type(data).__name__}")
        opt = lambda name: get_field(data, name, optional=True)  # noqa: E731
        return cls(
            text_field(data, "format"), text_field(data, "config"), text_field(data, "source"),
            record_field(data, "n", RowCounts.from_dict), record_map_field(data, "stages", StageResult.from_dict),
            number_field(data, "noise_floor_mm"), opt("noise_floor_source"), opt("noise_floor_specs_mm"),
            opt("noise_floor_repeats_mm"), records_field(data, "parameters", ParameterRow.from_dict, True) or (),
            records_field(data, "unidentifiable", unidentifiable_from_dict, True) or (), opt("condition_number"),
            opt("observability"), opt("sigma0"), opt("iterations"), opt("converged"),
            tuple(list_field(data, "rejected_points", True) or ()),
            records_field(data, "excluded_points", ExcludedPoint.from_dict, True) or (), opt("structure_note"),
            get_field(data, "T_tracker_base"), record_field(data, "method", MethodChoice.from_dict, True),
            record_field(data, "effects", EffectsReport.from_dict, True),
            record_field(data, "residual_choice", ResidualChoice.from_dict, True),
            record_field(data, "plausibility", Plausibility.from_dict, True),
            record_field(data, "residual_cv", ResidualCV.from_dict, True), object_field(data, "preparation", True),
            record_field(data, "multi_smr", MultiSmrReport.from_dict, True),
            record_field(data, "stop", StopSummary.from_dict, True), data.get("cell"), data.get("points"),
            tuple((k, data[k]) for k in IDENTIFICATION_KEYS if k in data),
            record_field(data, "summary", Summary.from_dict, True), text_field(data, "parameters_fit", True),
            records_field(data, "parameters_geometry_only", ParameterRow.from_dict, True),
            opt("parameters_sigma0"), record_field(data, "budget", _budget, True),
            record_field(data, "learning", LearningCurve.from_dict, True))


REPORT_KEYS = tuple(f.name for f in fields(CalibrationReport))[:_N_REPORT_KEYS]
PARAMETER_KEYS = ("parameters_fit", "parameters_sigma0", "parameters_geometry_only")     # written after ``parameters`` when present


def _budget(d: Mapping) -> ErrorBudget:
    """The error budget of report.json (``robocal.diagnose.budget``); a malformed one is a RecordError."""
    try:
        return ErrorBudget.from_dict(d)
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordError("budget", f"malformed error budget ({type(exc).__name__}: {exc})") from None
