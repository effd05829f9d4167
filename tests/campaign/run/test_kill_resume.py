"""SIGKILL a running mock campaign at random moments, resume each time, and check the log.

Every kill may only lose the point in flight: the bytes of all complete records written before the kill
must be byte-identical in the final log, and the final log must hold every planned point exactly once.
"""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np

from campaign.config.load import load_cell
from campaign.plan.build import build_plan
from campaign.run.log_reader import read_log
from tests.campaign.helpers import ROOT, small_config

import pytest

pytestmark = pytest.mark.system

KILLS = 12


def _start(cfg, run_dir, resume):
    args = [sys.executable, "-m", "campaign", "run", str(cfg)]
    args += ["--resume", str(run_dir)] if resume else ["--out", str(run_dir)]
    return subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONHASHSEED="0"))


def test_sigkill_at_random_moments_loses_nothing(tmp_path):
    cfg = small_config(tmp_path, **{"simulation.motion_time_s": 0.01, "plan.grid.step_mm": 300})
    run_dir = tmp_path / "run"
    log_path = run_dir / "log.jsonl"
    rng = np.random.default_rng(20261122)
    prefixes = []
    kills = 0
    for trial in range(KILLS + 10):
        resume = log_path.exists()
        proc = _start(cfg, run_dir, resume)
        if kills < KILLS:
            deadline = time.monotonic() + 30
            n0 = len(read_log(log_path).points) if resume else 0
            target = int(rng.integers(1, 5))               # kill after a random number of new points ...
            while time.monotonic() < deadline and proc.poll() is None:
                if log_path.exists() and len(read_log(log_path).points) >= n0 + target:
                    break
                time.sleep(0.002)
            time.sleep(rng.uniform(0.0, 0.03))              # ... plus a random fraction of a point
            proc.send_signal(signal.SIGKILL)
            proc.communicate(timeout=10)
            assert proc.returncode == -signal.SIGKILL, "the campaign finished before it could be killed"
            kills += 1
            if log_path.exists():
                contents = read_log(log_path)
                prefixes.append(log_path.read_bytes()[: contents.n_good_bytes])
            continue
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err.decode()
        break
    assert kills == KILLS
    final = log_path.read_bytes()
    for prefix in prefixes:
        assert final.startswith(prefix)
    contents = read_log(log_path)
    ids = [p["point_id"] for p in contents.points]
    planned = [p.point_id for p in build_plan(load_cell(cfg)).points]
    assert sorted(ids) == sorted(planned), "every planned point exactly once"
    assert contents.stops[-1]["exit_status"] == "success"
    assert (run_dir / "report.json").exists()
    print(f"{kills} SIGKILLs, {sum(e['type'] == 'resume' for e in contents.events)} resumes, "
          f"{len(ids)} points, {len(prefixes)} pre-kill prefixes byte-identical")


def test_a_run_stopped_after_its_first_nest_readings_resumes(tmp_path):
    """A run stops after the reference-nest readings that open it (ids ``N1@001``...: only nest records in the
    log, no robot point yet): resume accepts the log and finishes the plan, every point once."""
    from campaign.cli import main
    from tests.campaign.test_phenomena import NESTS

    cfg = small_config(tmp_path, **{"simulation.motion_time_s": 0.01, "plan.grid.step_mm": 600,
                                    "plan.test.count": 6, "plan.nests": {"every_n_points": 15, "points": NESTS}})
    run_dir = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run_dir)]) == 0
    lines = (run_dir / "log.jsonl").read_bytes().splitlines(keepends=True)
    first_robot = next(i for i, ln in enumerate(lines) if _is_point(ln) and "@" not in _pid(ln))
    assert first_robot >= 3 and all(_pid(ln).endswith("@001") for ln in lines[:first_robot] if _is_point(ln))
    planned = sorted(_pid(ln) for ln in lines if _is_point(ln))
    (run_dir / "log.jsonl").write_bytes(b"".join(lines[:first_robot]))     # killed before the first robot point
    assert main(["run", str(run_dir / "config.yaml"), "--resume", str(run_dir)]) == 0
    contents = read_log(run_dir)
    assert sorted(p["point_id"] for p in contents.points) == planned
    assert contents.stops[-1]["exit_status"] == "success"


def _is_point(line: bytes) -> bool:
    return json.loads(line)["kind"] == "point"


def _pid(line: bytes) -> str:
    return json.loads(line)["data"].get("point_id", "")
