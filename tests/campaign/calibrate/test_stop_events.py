"""The ``stop_check`` events of a ``plan.stop: auto`` run: always storable in the durable log, and read back into
the report's stop summary."""
from __future__ import annotations

import math

import pytest

from campaign.calibrate.adaptive_stop import StopCheck, stop_summary
from campaign.run.log_reader import read_log
from campaign.run.log_writer import RunLog

pytestmark = pytest.mark.unit
START = {"config_sha256": "ab" * 32, "plan_sha256": "cd" * 32, "config": {"name": "cell"},
         "created_utc": "2026-01-01T00:00:00Z", "software_version": "0.1.0",
         "units": {"q": "deg", "p": "mm", "t": "s"}}


def test_a_refit_too_early_for_a_prediction_is_logged_not_a_run_failure(tmp_path):
    """The first refit of a small block can have no finite prediction yet (fewer rows than parameters: inf). The
    log stores null there; an inf used to make the log refuse the event and fail the whole run."""
    early = StopCheck(20, math.inf, math.nan, 0.001, 0.03, 0.0, 0.05, 1.0, ((40, 0.04),), 1.0, "continue",
                      "too few points for a prediction yet")
    late = StopCheck(60, 0.035, 0.0001, 0.001, 0.03, 0.0, 0.05, 1.0, ((60, 0.035),), 3.0, "stop", "gain too small")
    with RunLog.create(tmp_path / "run", START) as log:
        log.append_event(early)
        log.append_event(late)
        log.close("success", "done")
    contents = read_log(tmp_path / "run")
    first = contents.events[0]
    assert first["predicted_rms_mm"] is None and first["gain_next_mm"] is None and first["curve"] == [[40, 0.04]]
    summary = stop_summary(contents, 0.036)
    assert summary.n_calib_at_stop == 60 and summary.predicted_rms_mm == 0.035 and len(summary.checks) == 1


def test_a_point_record_with_a_non_finite_value_is_still_refused(tmp_path):
    """Only events (notes about the run) are made storable; a measurement with inf is an error, as before."""
    from campaign.run.log_reader import RunLogError

    with RunLog.create(tmp_path / "run", START) as log:
        with pytest.raises(RunLogError, match="not storable"):
            log.append_point({"point_id": "P0", "set": "calib", "kind": "plan", "q_cmd_deg": [0.0] * 6,
                               "p_tracker_mm": [math.inf, 0.0, 0.0], "t_start_s": 0.0, "t_end_s": 1.0})
        log.close("fail", "test")
