"""Signals always win (issue 25): SIGTERM at a random moment of ``reprocess``, ``diagnose`` and ``report`` gives exit
130 with one line on stderr, never a traceback or "Exception ignored", and every output file is complete or
absent (no temporary file left, the sources untouched).

One small run is prepared once; each trial is the real entry point (``python -m campaign``) on a fresh directory.
The signal is sent at a uniformly random time within the command's duration (measured on an uninterrupted run of
the same command), counted from the moment the process has installed its handler (``SigCgt`` in
``/proc/PID/status``): before that instant the interpreter is still starting and the signal's default action
applies, which no program can change.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from campaign.run.log_reader import read_log
from tests.campaign.helpers import ROOT, small_config

pytestmark = [pytest.mark.system,
              pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc (Linux)")]

SEED = 20261126
COMMANDS = ("reprocess", "diagnose", "report")
PNG_END = b"IEND\xaeB`\x82"
LEAN = {"calibration.effects": "none", "calibration.residual": "none"}     # every phase, fewer CV fits: cheaper


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """One finished small run (its data.csv, log and report), shared by every trial."""
    from campaign.cli import main

    root = tmp_path_factory.mktemp("signals")
    cfg = small_config(root, **LEAN)
    assert main(["run", str(cfg), "--out", str(root / "run")]) == 0
    return {"config": cfg, "run": root / "run"}


def _argv(command: str, prepared: dict, work: Path) -> list[str]:
    """The command line of one trial in the fresh directory ``work`` (the run copied there when it is written to)."""
    cfg, run = str(prepared["config"]), prepared["run"]
    if command == "reprocess":
        return ["reprocess", str(run / "data.csv"), "--config", cfg, "--out", str(work / "out")]
    shutil.copytree(run, work / "run")
    if command == "diagnose":                        # writes diagnosis.json and rewrites report.html + figures
        return ["diagnose", str(work / "run"), "--config", cfg]
    return ["report", str(work / "run"), "--out", str(work / "copy.html")]


def _checksums(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _handler_installed(pid: int) -> bool:
    """True once the process catches SIGTERM (its handler is installed)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def _start(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "campaign", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))


def _complete(path: Path) -> str | None:
    """Why the output file ``path`` is not complete (None when it is)."""
    data = path.read_bytes()
    if path.name.startswith(".") and path.name.endswith(".tmp"):
        return "temporary file left behind"
    if path.suffix == ".json":
        try:
            json.loads(data)
        except ValueError as exc:
            return f"not valid JSON: {exc}"
    elif path.suffix == ".png":
        if not (data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(PNG_END)):
            return "truncated PNG"
    elif path.suffix == ".html":
        if not data.rstrip().endswith(b"</html>"):
            return "truncated HTML"
    elif path.name == "log.jsonl":
        read_log(path)
    elif path.suffix in (".csv", ".yaml", ".log"):
        if data and not data.endswith(b"\n"):
            return "truncated text file"
    else:
        return "unexpected file"
    return None


def _trial(command: str, prepared: dict, work: Path, delay_s: float | None) -> tuple[int, str, float]:
    """Run one command in ``work``; with ``delay_s``, SIGTERM it that long after its handler is installed.
    Returns (exit code, stderr, seconds from the handler to the end)."""
    argv = _argv(command, prepared, work)
    before = _checksums(prepared["run"])
    proc = _start(argv)
    deadline = time.monotonic() + 30
    while not _handler_installed(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.001)
    t0 = time.monotonic()
    if delay_s is not None:
        time.sleep(delay_s)
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert _checksums(prepared["run"]) == before, "the source run was modified"
    return proc.returncode, err.decode(), time.monotonic() - t0


SIGNALS_PER_COMMAND = {"reprocess": 34, "diagnose": 33, "report": 33}      # 100 in all


@pytest.mark.timeout(900)
@pytest.mark.parametrize("command", COMMANDS)
def test_sigterm_at_random_moments_exit_130_with_complete_or_absent_outputs(command, prepared, tmp_path):
    n_signals = SIGNALS_PER_COMMAND[command]
    code, err, duration = _trial(command, prepared, tmp_path / "reference", None)   # uninterrupted: its duration
    assert code == 0 and not err.strip(), err
    rng = np.random.default_rng([SEED, COMMANDS.index(command)])
    done, finished_first, failures = 0, 0, []
    for k in range(3 * n_signals):
        if done == n_signals:
            break
        work = tmp_path / f"t{k:03d}"
        work.mkdir()
        delay = float(rng.uniform(0.0, duration))
        code, err, seconds = _trial(command, prepared, work, delay)
        if code == 0 and not err.strip():            # the command ended before the signal (the machine is less
            finished_first += 1                      # loaded than during the reference run): shorter, draw again
            duration = min(duration, seconds)
            shutil.rmtree(work)
            continue
        done += 1
        lines = err.strip().splitlines()
        problems = [] if code == 130 else [f"exit {code}"]
        problems += [] if len(lines) == 1 else [f"{len(lines)} stderr lines"]
        problems += ["traceback"] if "Traceback" in err or "Exception ignored" in err else []
        problems += [f"{p.relative_to(work)}: {why}" for p in sorted(work.rglob("*"))     # copies of the run too
                     if p.is_file() and (why := _complete(p))]
        if problems:
            failures.append(f"+{delay:.3f} s: {'; '.join(problems)}: {err.strip()[-300:]}")
        shutil.rmtree(work)
    print(f"{command}: {done} SIGTERMs within {duration:.2f} s of the handler, {finished_first} runs ended before "
          "their signal")
    assert done == n_signals
    assert not failures, f"{len(failures)} of {done} failed:\n" + "\n".join(failures[:10])
