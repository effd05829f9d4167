"""A kill study of ``campaign run`` (issue 36): SIGKILL at seeded random instants over a whole run (directory set-up,
plan, measuring, calibration, figures, report), then recovery as the README says: ``run --resume DIR``, or, where
resume refuses, ``run --out DIR --overwrite``. Each trial checks that every file in the directory is complete or
absent right after the kill, that the recovery ends with exit 0, and that every planned point is in the log exactly
once (0 lost, 0 duplicated). Used by ``tests/campaign/test_kill_study.py`` (a few kills) and ``bench/bench_kill.py``
(the study: 100 kills or more)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
PHASES = ("no directory", "set-up (no log)", "measuring", "calibrating", "report", "finished")


@dataclass(frozen=True)
class Trial:
    delay_s: float
    phase: str               # where the kill landed (from the directory's state)
    recovery: str            # "none", "resume", "overwrite", "fresh"
    exit_code: int
    lost: int
    duplicated: int
    torn_files: tuple[str, ...]


def command(argv, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "TMPDIR": str(cwd)}
    return subprocess.run([sys.executable, "-m", "campaign", *map(str, argv)], cwd=ROOT, env=env,
                          capture_output=True, timeout=timeout)


def start(argv, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "TMPDIR": str(cwd)}
    return subprocess.Popen([sys.executable, "-m", "campaign", *map(str, argv)], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def phase_of(run: Path) -> str:
    """Where a run was cut, from what its directory holds."""
    if not run.exists():
        return PHASES[0]
    log = run / "log.jsonl"
    if not log.exists():
        return PHASES[1]
    kinds = [json.loads(line)["kind"] for line in log.read_text().splitlines() if line.strip().endswith("}")]
    if "stop" not in kinds:
        return PHASES[2]
    if not (run / "model.json").exists():
        return PHASES[3]
    return PHASES[5] if (run / "report.html").exists() else PHASES[4]


def torn(run: Path) -> list[str]:
    """Files of the directory (temporaries aside) that are not complete: JSON that does not parse, a PNG without
    its end chunk, an HTML page without its end, a CSV without its final line end."""
    bad = []
    for p in run.rglob("*") if run.exists() else ():
        if not p.is_file() or p.name.endswith(".tmp") or p.name == "log.jsonl" or p.name == "campaign.log":
            continue
        data = p.read_bytes()
        ok = {".json": lambda: bool(json.loads(data)) or True, ".png": lambda: data.endswith(b"IEND\xaeB`\x82"),
              ".html": lambda: data.rstrip().endswith(b"</html>"), ".csv": lambda: data.endswith(b"\n"),
              ".yaml": lambda: yaml.safe_load(data) is not None}.get(p.suffix, lambda: True)
        try:
            if not ok():
                bad.append(str(p.relative_to(run)))
        except ValueError:
            bad.append(str(p.relative_to(run)))
    return bad


def point_ids(run: Path) -> list[str]:
    return [json.loads(line)["data"]["point_id"] for line in (run / "log.jsonl").read_text().splitlines()
            if json.loads(line)["kind"] == "point"]


def trial(config: Path, run: Path, delay_s: float, planned: list[str]) -> Trial:
    """One kill after ``delay_s`` s, then the recovery; ``planned`` the point ids of a complete run."""
    proc = start(["run", config, "--out", run], run.parent)
    time.sleep(delay_s)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    proc.wait()
    phase, broken = phase_of(run), torn(run)
    if proc.returncode == 0:
        recovery, result = "none", subprocess.CompletedProcess([], 0)
    elif not run.exists():
        recovery, result = "fresh", command(["run", config, "--out", run], run.parent)
    else:
        recovery, result = "resume", command(["run", config, "--resume", run], run.parent)
        if result.returncode == 2:
            recovery, result = "overwrite", command(["run", config, "--out", run, "--overwrite"], run.parent)
    got = Counter(point_ids(run)) if (run / "log.jsonl").exists() else Counter()
    lost = sum(1 for pid in planned if got[pid] == 0)
    dup = sum(c - 1 for c in got.values() if c > 1)
    return Trial(delay_s, phase, recovery, result.returncode, lost, dup, tuple(broken))


def phase_times(config: Path, workdir: Path) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """An uninterrupted run, its directory's phase polled every 10 ms: {phase: (first seen, last seen)} in s
    since its start, and the point ids of the complete run."""
    reference = workdir / "reference"
    proc = start(["run", config, "--out", reference], workdir)
    t0, seen = time.monotonic(), {}
    while proc.poll() is None:
        t = time.monotonic() - t0
        phase = phase_of(reference)
        seen[phase] = (seen.get(phase, (t, t))[0], t)
        time.sleep(0.01)
    assert proc.returncode == 0, "the uninterrupted run failed"
    return seen, point_ids(reference)


def study(config: Path, workdir: Path, kills: int, seed: int) -> list[Trial]:
    """``kills`` trials at instants drawn in turn from each phase an uninterrupted run went through (uniform
    within the phase's time span, widened by 50 ms), so that short phases are hit as often as long ones."""
    spans, planned = phase_times(config, workdir)
    rng = np.random.default_rng(seed)
    order = [spans[p] for p in PHASES if p in spans]
    delays = [float(rng.uniform(max(lo - 0.05, 0.0), hi + 0.05)) for lo, hi in
              (order[k % len(order)] for k in range(kills))]
    return [trial(config, workdir / f"run{k:03d}", d, planned) for k, d in enumerate(delays)]


def summary(trials: list[Trial]) -> dict:
    return {"kills": len(trials), "phases": dict(Counter(t.phase for t in trials)),
            "recoveries": dict(Counter(t.recovery for t in trials)),
            "failed": sum(t.exit_code != 0 for t in trials), "lost": sum(t.lost for t in trials),
            "duplicated": sum(t.duplicated for t in trials), "torn": sum(bool(t.torn_files) for t in trials)}
