"""The ``stop_check`` events of a ``plan.stop: auto`` run: always storable in the log, and read back into the
report's stop summary."""
from __future__ import annotations

import json
import math

import pytest

from campaign.calibrate.adaptive_stop import StopCheck, stop_summary
from campaign.run.log_reader import LogContents

pytestmark = pytest.mark.unit


def test_a_refit_too_early_for_a_prediction_is_logged_as_json_not_as_a_run_failure():
    """The first refit of a small block can have no finite prediction yet (fewer rows than parameters: inf). The
    event stores null there; an inf used to make the log refuse the record and fail the whole run."""
    early = StopCheck(20, math.inf, math.nan, 0.001, 0.03, 0.0, 0.05, 1.0, ((40, 0.04),), 1.0, "continue",
                      "too few points for a prediction yet")
    event = early.to_event()
    json.dumps(event, allow_nan=False)
    assert event["predicted_rms_mm"] is None and event["gain_next_mm"] is None and event["curve"] == [[40, 0.04]]
    late = StopCheck(60, 0.035, 0.0001, 0.001, 0.03, 0.0, 0.05, 1.0, ((60, 0.035),), 3.0, "stop", "gain too small")
    contents = LogContents(start={}, events=[event, late.to_event()])
    summary = stop_summary(contents, 0.036)
    assert summary.n_calib_at_stop == 60 and summary.predicted_rms_mm == 0.035 and len(summary.checks) == 1
