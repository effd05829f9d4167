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
    aim: str = ""            # the phase the kill was aimed at
    error: str = ""          # the recovery's last stderr line when it failed


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


def points_logged(run: Path) -> int:
    """Point records in a run's log so far (0 without a log)."""
    try:
        return (run / "log.jsonl").read_bytes().count(b'"kind":"point"')
    except OSError:
        return 0


def trial(config: Path, run: Path, target: str, offset_s: float, planned: list[str], after_points: int = 0) -> Trial:
    """One kill ``offset_s`` s after the run is first seen in phase ``target`` or a later one (after its start for
    the first phase; for ``measuring``, once ``after_points`` points are logged), then the recovery; ``planned`` the
    point ids of a complete run. Anchoring the kill on the run's own progress, not on the time since its start,
    keeps the instants spread over the run whatever the load."""
    proc = start(["run", config, "--out", run], run.parent)
    t0 = time.monotonic()
    while proc.poll() is None and (PHASES.index(phase_of(run)) < PHASES.index(target)
                                   or (target == "measuring" and phase_of(run) == target
                                       and points_logged(run) < after_points)):
        time.sleep(0.005)
    time.sleep(offset_s)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    delay_s = time.monotonic() - t0
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
    error = "" if result.returncode == 0 else (result.stderr or b"").decode(errors="replace").strip()[-400:]
    return Trial(delay_s, phase, recovery, result.returncode, lost, dup, tuple(broken), target, error)


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


def without_acceptance(config: Path, workdir: Path) -> Path:
    """The config without its ``acceptance`` thresholds (a copy in ``workdir``): a resumed run measures its
    remaining points with other noise than an uninterrupted one, and on a small test set that can move the
    held-out RMS across a threshold (exit 4, every output written). The study judges durability, so every
    recovery must end with exit 0."""
    doc = yaml.safe_load(Path(config).read_text())
    if "acceptance" not in doc:
        return Path(config)
    doc.pop("acceptance")
    out = workdir / f"{Path(config).stem}-no-acceptance.yaml"
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


def study(config: Path, workdir: Path, kills: int, seed: int) -> list[Trial]:
    """``kills`` trials aimed in turn at each phase an uninterrupted run went through, each at an instant uniform
    within that phase's time span in the reference run (widened by 50 ms) after the trial enters it (while
    measuring: after a random number of logged points, within one point's time), so that short phases are hit as
    often as long ones."""
    config = without_acceptance(config, workdir)
    spans, planned = phase_times(config, workdir)
    rng = np.random.default_rng(seed)
    order = [p for p in PHASES if p in spans]
    aims = [order[k % len(order)] for k in range(kills)]
    trials = []
    for k, p in enumerate(aims):
        span = spans[p][1] - spans[p][0]
        if p == "measuring":            # after a random number of points, within one point's time
            after, offset = int(rng.integers(0, len(planned))), float(rng.uniform(0.0, span / len(planned) + 0.02))
        else:
            after, offset = 0, float(rng.uniform(0.0, span + 0.05))
        trials.append(trial(config, workdir / f"run{k:03d}", p, offset, planned, after))
    return trials


def summary(trials: list[Trial]) -> dict:
    return {"kills": len(trials), "aimed": dict(Counter(t.aim for t in trials)),
            "phases": dict(Counter(t.phase for t in trials)),
            "recoveries": dict(Counter(t.recovery for t in trials)),
            "failed": sum(t.exit_code != 0 for t in trials), "lost": sum(t.lost for t in trials),
            "duplicated": sum(t.duplicated for t in trials), "torn": sum(bool(t.torn_files) for t in trials)}
