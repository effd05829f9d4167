"""``verify.json`` as a typed record: ``VerifyReport`` (built by ``campaign.correct.verify``)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from campaign.calibrate.report_sections import ErrorFigures, VerifyPass
from campaign.io.json_fields import (RecordError, count_field, number_field, object_field, record_dict,
                                     record_map_field, records_field, text_field)

VERIFY_FORMAT = "campaign-verify/2"
VERIFY_FORMAT_1 = "campaign-verify/1"          # earlier verify.json: no passes, no definitions
UNCORRECTED = "uncorrected (planned joints)"   # stages of every verify.json: the test points at their planned joints ...
POOLED = "after correction (all passes pooled)"     # ... and every corrected pass pooled


@dataclass(frozen=True, eq=False)
class VerifyReport:
    """``verify.json``: closed-loop verification of a run's test points (``campaign.correct.verify.verify_run``).

    ``n`` test points; ``noise_floor_mm`` (RMS of the measurement sigma at the targets); ``n_uncorrected`` points
    held at their planned joints in the last pass (None when nothing was measured corrected); ``stages`` error
    statistics per stage (mm); ``passes`` one summary per pass; ``exit_status``/``reason`` of the measuring run;
    ``definitions`` of the terms; ``created_utc`` ISO time; ``drift`` the tracker drift removed with the reference
    nests (``campaign.correct.verify_drift``; None when the config has none).
    """

    format: str
    run: str
    n: int
    noise_floor_mm: float
    n_uncorrected: int | None
    stages: dict[str, ErrorFigures]
    passes: tuple[VerifyPass, ...]
    exit_status: str
    reason: str
    definitions: dict
    created_utc: str
    drift: dict | None = None

    def to_dict(self) -> dict:
        """The verify.json object."""
        return record_dict(self, omit_none=("drift",))

    @classmethod
    def from_dict(cls, data: Mapping) -> "VerifyReport":
        """A verify.json object (also of format ``campaign-verify/1``, without passes and definitions);
        RecordError names a missing field or one of the wrong kind (by its path, ``passes.0.all.rms_mm``)."""
        if not isinstance(data, Mapping):
            raise RecordError("verify", f"expected an object, got {type(data).__name__}")
        old = data.get("format") == VERIFY_FORMAT_1
        return cls(text_field(data, "format"), text_field(data, "run"), count_field(data, "n"),
                   number_field(data, "noise_floor_mm"), count_field(data, "n_uncorrected", True),
                   record_map_field(data, "stages", ErrorFigures.from_dict),
                   records_field(data, "passes", VerifyPass.from_dict, old) or (), text_field(data, "exit_status"),
                   text_field(data, "reason"), object_field(data, "definitions", old) or {},
                   text_field(data, "created_utc"), object_field(data, "drift", True))
