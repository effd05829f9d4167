"""``report.json`` as a typed record: ``CalibrationReport`` (built by ``campaign.calibrate.stages``)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

from campaign.io.json_fields import RecordError, ReportMapping, get_field, number_field, object_field, text_field


IDENTIFICATION_KEYS = ("robot_identity", "tracker_identity", "driver_versions", "software_version", "identity_check")
_N_REPORT_KEYS = 26                                       # the always-present report.json keys, before multi_smr


@dataclass(frozen=True, eq=False)
class CalibrationReport(ReportMapping):
    """``report.json``: the calibration's figures (see ``campaign.calibrate.stages.calibrate_dataset``).

    ``n`` row counts (calib/test/check/rejected); ``stages`` per-stage error statistics on the test rows (mm);
    ``noise_floor_mm`` with its source ("repeats" or "specs") and both candidates; the identified ``parameters``
    and their diagnostics; ``T_tracker_base`` (4, 4) registration (mm); the method and effect choices; optional
    ``multi_smr``; ``stop`` (``plan.stop: auto`` runs: every refit's predicted held-out RMS curve and decision,
    with the held-out RMS measured at the end); ``cell`` summary and per-point ``points`` table (HTML figures); the
    hardware ``identification`` of the run log (robot/tracker identity, driver and software versions) when processed
    from a log.
    """

    format: str
    config: str
    source: str
    n: dict
    stages: dict
    noise_floor_mm: float
    noise_floor_source: str
    noise_floor_specs_mm: float
    noise_floor_repeats_mm: float | None
    parameters: list
    unidentifiable: list
    condition_number: float
    observability: Any
    sigma0: float
    iterations: int
    converged: bool
    rejected_points: list
    excluded_points: list
    structure_note: str | None
    T_tracker_base: list
    method: dict
    effects: dict
    residual_choice: dict | None
    plausibility: dict | None
    residual_cv: dict | None
    preparation: dict | None
    multi_smr: dict | None = None
    stop: dict | None = None
    cell: Any = None
    points: Any = None
    identification: tuple[tuple[str, Any], ...] = ()

    def to_dict(self) -> dict:
        """The report.json object (the key order written so far)."""
        out = {name: getattr(self, name) for name in REPORT_KEYS}
        if self.multi_smr is not None:
            out["multi_smr"] = self.multi_smr
        if self.stop is not None:
            out["stop"] = self.stop
        out["cell"], out["points"] = self.cell, self.points
        out.update(self.identification)
        return out

    def with_identification(self, ident: Mapping) -> "CalibrationReport":
        """A copy carrying the run log's hardware identification (``robot_identity``... ``software_version``)."""
        return replace(self, identification=tuple((k, ident[k]) for k in IDENTIFICATION_KEYS if k in ident))

    @classmethod
    def from_dict(cls, data: Mapping) -> "CalibrationReport":
        """A report.json object; RecordError names a missing field or one of the wrong kind."""
        if not isinstance(data, Mapping):
            raise RecordError("report", f"expected an object, got {type(data).__name__}")
        for check, name in ((text_field, "format"), (text_field, "config"), (text_field, "source"), (object_field, "n"), (object_field, "stages"),
                            (number_field, "noise_floor_mm"), (get_field, "T_tracker_base")):
            check(data, name)
        args = {name: get_field(data, name, optional=True) for name in REPORT_KEYS}
        return cls(**args, multi_smr=object_field(data, "multi_smr", True), stop=object_field(data, "stop", True),
                   cell=data.get("cell"), points=data.get("points"),
                   identification=tuple((k, data[k]) for k in IDENTIFICATION_KEYS if k in data))


REPORT_KEYS = tuple(f.name for f in fields(CalibrationReport))[:_N_REPORT_KEYS]
