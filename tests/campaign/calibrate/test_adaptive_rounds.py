"""``plan.kind: adaptive`` on the mock cell: seed, rounds chosen with the refitted model, a stop within the pose
budget, the test set after it, the report's stop and learning sections; killed (SIGKILL) in the middle of a round
and resumed: the round's logged batch is finished, nothing is lost or measured twice."""
from __future__ import annotations

import pytest

from campaign.calibrate.adaptive_rounds import round_checks
from campaign.run.log_reader import read_log
from tests.campaign.calibrate.test_adaptive_stop import EFFECTS, _killed_when, _start
from tests.campaign.helpers import read_report, small_config

pytestmark = pytest.mark.system

BUDGET = 90


def test_adaptive_run_stops_itself_and_resumes_a_killed_round(tmp_path):
    path = small_config(tmp_path, **{"plan.pool": {"step_mm": 200, "tilts": 2}, "plan.kind": "adaptive",
                                     "plan.max_points": BUDGET, "simulation.effects": EFFECTS,
                                     "simulation.motion_time_s": 0.01})
    run_dir = tmp_path / "run"
    log_path = run_dir / "log.jsonl"
    measured = lambda c: {p["point_id"] for p in c.points}  # noqa: E731

    def mid_round(c):                                       # a batch logged, some of it measured, not all
        rounds = [r for r in round_checks(c) if r.decision == "continue"]
        return bool(rounds) and 2 <= len(set(rounds[-1].added) & measured(c)) < len(rounds[-1].added)
    _killed_when(_start(path, run_dir, False), log_path, mid_round)
    before = read_log(log_path)
    prefix = log_path.read_bytes()[: before.n_good_bytes]
    killed = [r for r in round_checks(before) if r.decision == "continue"][-1]
    proc = _start(path, run_dir, True)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err.decode()

    assert log_path.read_bytes().startswith(prefix), "nothing written before the kill changed"
    contents = read_log(log_path)
    ids = [p["point_id"] for p in contents.points]
    assert len(ids) == len(set(ids)), "every point measured once"
    rounds = round_checks(contents)
    assert killed in rounds, "the killed round was not decided again"
    assert set(killed.added) <= set(ids), "the killed round's batch was finished after the resume"
    stop = rounds[-1]
    assert stop.decision == "stop" and sum(r.decision == "stop" for r in rounds) == 1
    calib = [p["point_id"] for p in contents.points if p["set"] == "calib"]
    seed = [row.split(",")[0] for row in (run_dir / "plan.csv").read_text().splitlines()[1:] if ",calib," in row]
    batches = [i for r in rounds for i in r.added]
    assert calib == seed + batches, "the seed, then every logged batch in its order, nothing else"
    assert stop.n_calib == len(calib) < BUDGET, "the run stopped by itself within the pose budget"
    assert "lower the predicted held-out RMS" in stop.reason
    plan_tests = sum(",test," in row for row in (run_dir / "plan.csv").read_text().splitlines())
    assert sum(p["set"] == "test" for p in contents.points) == plan_tests
    report = read_report(run_dir)
    assert report.stop.n_calib_at_stop == len(calib)
    assert report.learning.measured[-1] == (len(calib), pytest.approx(report.final.test.rms_mm))
    assert 0 < report.learning.minutes_measured < report.learning.minutes_planned   # stopped before the budget
    assert report.final.test.rms_mm < 1.25 * report.noise_floor_mm
    assert sum(e["type"] == "resume" for e in contents.events) == 1
