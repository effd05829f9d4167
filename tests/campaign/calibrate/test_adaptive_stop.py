"""``plan.stop: auto`` runs on the mock cell: the refits, the stop, the test set after it, the report, and a run
paused by tracker faults and resumed until it is done."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from campaign.run.log_reader import read_log
from tests.campaign.helpers import ROOT, read_report, small_config
from tests.campaign.hostile import cli

pytestmark = pytest.mark.system

EFFECTS = [{"name": "joint_compliance", "params": {"values": [1.0e-6, 2.0e-6]}},
           {"name": "gear_cyclic", "params": {"joint": 2, "values": [1.4e-4, 1.4e-4, 7.0e-5, 7.0e-5]}}]


def _config(tmp_path, **over):
    return small_config(tmp_path, **{"plan.pool": {"step_mm": 200, "tilts": 2}, "plan.kind": "optimal",
                                      "plan.stop": "auto", "plan.points": 120, "plan.block_points": 10,
                                      "simulation.effects": EFFECTS, **over})


def _check_run(run_dir):
    contents = read_log(run_dir)
    ids = [p["point_id"] for p in contents.points]
    assert len(ids) == len(set(ids)), "every point measured once"
    checks = [e for e in contents.events if e["type"] == "stop_check"]
    stops = [c for c in checks if c["decision"] == "stop"]
    assert len(stops) == 1 and stops[0] is checks[-1]
    n_cal = sum(p["set"] == "calib" for p in contents.points)
    plan = (run_dir / "plan.csv").read_text().splitlines()[1:]
    assert n_cal == stops[0]["n_calib"] < sum(",calib," in row for row in plan)
    assert sum(p["set"] == "test" for p in contents.points) == sum(",test," in row for row in plan)
    report = read_report(run_dir)
    stop = report.stop
    assert stop.n_calib_at_stop == n_cal
    assert stop.measured_rms_mm == report.final.test.rms_mm
    curve = dict(map(tuple, stop.last_curve))
    assert curve[n_cal] == pytest.approx(stop.predicted_rms_mm)
    assert all(a >= b - 1e-12 for a, b in zip(list(curve.values()), list(curve.values())[1:]))   # more points help
    assert abs(stop.predicted_rms_mm / stop.measured_rms_mm - 1) < 0.3
    assert not any("incomplete run" in n for n in report.plausibility.notes)
    return stop


def test_stop_auto_refits_after_blocks_stops_and_measures_the_test_set(tmp_path, capsys):
    code, out, err = cli(capsys, "run", _config(tmp_path), "--out", tmp_path / "run")
    assert code == 0, err
    stop = _check_run(tmp_path / "run")
    assert "Predicted held-out RMS vs calibration points" in out and f"stopped after {stop.n_calib_at_stop}" in out
    assert (tmp_path / "run" / "report.html").read_text().count('id="stop-table"') == 1


def _killed_when(proc, log_path, ready, timeout_s=120):
    """SIGKILL ``proc`` once ``ready(contents)`` holds for its log."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        if log_path.exists() and ready(read_log(log_path)):
            proc.send_signal(signal.SIGKILL)
            proc.communicate(timeout=10)
            assert proc.returncode == -signal.SIGKILL
            return
        time.sleep(0.01)
    raise AssertionError(f"the run ended (exit {proc.poll()}) before it could be killed")


def _start(path, run_dir, resume):
    args = [sys.executable, "-m", "campaign", "run", str(path)]
    args += ["--resume", str(run_dir)] if resume else ["--out", str(run_dir)]
    return subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def test_stop_auto_resumes_inside_a_block_and_after_the_stop(tmp_path):
    """Killed in the first block, then again after the stop decision while the test set is measured: the resumed
    run finishes the block, refits, and after the stop measures only what is left of the test set."""
    path = _config(tmp_path, **{"simulation.motion_time_s": 0.01})
    run_dir = tmp_path / "run"
    log_path = run_dir / "log.jsonl"
    calib = lambda c: sum(p["set"] == "calib" for p in c.points)  # noqa: E731
    _killed_when(_start(path, run_dir, False), log_path, lambda c: calib(c) >= 20)
    stopped = lambda c: any(e.get("decision") == "stop" for e in c.events)  # noqa: E731
    _killed_when(_start(path, run_dir, True), log_path,
                 lambda c: stopped(c) and sum(p["set"] == "test" for p in c.points) >= 3)
    proc = _start(path, run_dir, True)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()
    contents = read_log(log_path)
    assert sum(e["type"] == "resume" for e in contents.events) == 2
    _check_run(run_dir)
