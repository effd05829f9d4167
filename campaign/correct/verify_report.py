"""``verify.json`` as a typed record: ``VerifyReport`` (built by ``campaign.correct.verify``)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

from campaign.io.json_fields import (RecordError, ReportMapping, check_field, count_field, number_field, object_field,
                                     text_field)


@dataclass(frozen=True, eq=False)
class VerifyReport(ReportMapping):
    """``verify.json``: closed-loop verification of a run's test points (``campaign.correct.verify.verify_run``).

    ``n`` test points; ``noise_floor_mm`` (RMS of the measurement sigma at the targets); ``n_uncorrected`` points
    held at their planned joints in the last pass (None when nothing was measured corrected); ``stages`` error
    statistics per stage (mm); ``passes`` one summary per pass; ``exit_status``/``reason`` of the measuring run;
    ``definitions`` of the terms; ``created_utc`` ISO time.
    """

    format: str
    run: str
    n: int
    noise_floor_mm: float
    n_uncorrected: int | None
    stages: dict
    passes: list
    exit_status: str
    reason: str
    definitions: dict
    created_utc: str

    def to_dict(self) -> dict:
        """The verify.json object."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping) -> "VerifyReport":
        """A verify.json object; RecordError names a missing field or one of the wrong kind."""
        if not isinstance(data, Mapping):
            raise RecordError("verify", f"expected an object, got {type(data).__name__}")
        return cls(text_field(data, "format"), text_field(data, "run"), count_field(data, "n"), number_field(data, "noise_floor_mm"),
                   count_field(data, "n_uncorrected", True), object_field(data, "stages"), check_field(data, "passes", False, lambda v: isinstance(v, list), "a list"),
                   text_field(data, "exit_status"), text_field(data, "reason"), object_field(data, "definitions"),
                   text_field(data, "created_utc"))
