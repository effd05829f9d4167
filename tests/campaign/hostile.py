"""Shared machinery of the hostile-input tables (issue 12): run the CLI in-process, check the one-line contract,
snapshot directories to prove nothing was written or modified."""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

from campaign.cli import main


def cli(capsys, *argv) -> tuple[int, str, str]:
    """Run ``campaign ARGV`` in-process; (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(code: int, out: str, err: str, expected_code: int, *needles: str) -> str:
    """Exact exit code, no traceback anywhere, stderr exactly one line containing every needle."""
    text = out + err
    assert "Traceback" not in text and 'File "' not in text, text[-2000:]
    assert code == expected_code, f"exit {code}, expected {expected_code}: {err.strip()[:500]}"
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"stderr must be one line, got {len(lines)}: {err[:800]}"
    for needle in needles:
        assert needle in lines[0], f"{needle!r} not in {lines[0]!r}"
    return lines[0]


def snapshot(*roots: Path) -> dict[str, str]:
    """path -> sha256 of every file (and '<dir>' for every directory) under ``roots``."""
    state = {}
    for root in roots:
        root = Path(root)
        if not root.exists():
            continue
        for p in sorted([root, *root.rglob("*")]):
            state[str(p)] = "<dir>" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return state


SECRET = "S3cr3t-pa55w0rd-7f1d"          # in every hostile subprocess's environment; must never be written


def checksums(*roots: Path) -> dict[str, str]:
    """path -> sha256 of every file under ``roots``."""
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest()
            for root in roots for p in sorted(Path(root).rglob("*")) if p.is_file()}


def _process_args(argv, tmp: Path, env: dict | None, code: str | None) -> tuple[list[str], dict, Path]:
    (tmp / "tmp").mkdir(exist_ok=True)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "TMPDIR": str(tmp / "tmp"), "RWS_USER": "calib", "RWS_PASSWORD": SECRET,
           "PYTHONWARNINGS": "error::ResourceWarning", "OPENBLAS_NUM_THREADS": "1", **(env or {})}
    head = ["-c", code] if code is not None else ["-m", "campaign"]
    return [sys.executable, *head, *map(str, argv)], env, root


def run_campaign_process(argv, tmp: Path, env: dict | None = None, code: str | None = None,
                         timeout: float = 300) -> tuple[int, str, str]:
    """``python -m campaign ARGV`` (or ``python -c CODE ARGV``) with the repository on the path, crash reports
    in TMP/tmp, the secret in RWS_PASSWORD and ResourceWarnings as errors; (exit code, stdout, stderr)."""
    args, env, root = _process_args(argv, tmp, env, code)
    proc = subprocess.run(args, cwd=root, env=env, capture_output=True, timeout=timeout)
    return proc.returncode, proc.stdout.decode("utf-8", "replace"), proc.stderr.decode("utf-8", "replace")


def start_campaign_process(argv, tmp: Path, env: dict | None = None, code: str | None = None) -> subprocess.Popen:
    """:func:`run_campaign_process` started in the background (stdout and stderr piped)."""
    args, env, root = _process_args(argv, tmp, env, code)
    return subprocess.Popen(args, cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def finish(proc: subprocess.Popen, timeout: float = 300) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of a process from :func:`start_campaign_process`."""
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace")


def barrier_code(module: str, attribute: str, ready: Path, go: Path) -> str:
    """``python -c`` code running the CLI with ``module.attribute`` (a function or method, ``Class.method``)
    wrapped: on its first call the process writes ``ready`` and waits until ``go`` exists (a deterministic
    interleaving of two commands)."""
    owner, _, name = attribute.rpartition(".")
    return (f"import importlib, os, sys, time\n"
            f"m = importlib.import_module({module!r})\n"
            f"holder = getattr(m, {owner!r}) if {owner!r} else m\n"
            f"orig = getattr(holder, {name!r})\n"
            f"state = {{'first': True}}\n"
            f"def wrapped(*a, **k):\n"
            f"    if state['first']:\n"
            f"        state['first'] = False\n"
            f"        open({str(ready)!r}, 'w').close()\n"
            f"        while not os.path.exists({str(go)!r}):\n"
            f"            time.sleep(0.02)\n"
            f"    return orig(*a, **k)\n"
            f"setattr(holder, {name!r}, wrapped)\n"
            f"from campaign.cli import main\n"
            f"sys.exit(main())\n")


def kill_code(module: str, attribute: str, after: bool = True) -> str:
    """``python -c`` code running the CLI with ``module.attribute`` wrapped to SIGKILL the process on its first
    call, after it returned (``after``) or before it runs."""
    owner, _, name = attribute.rpartition(".")
    return (f"import importlib, os, signal, sys\n"
            f"m = importlib.import_module({module!r})\n"
            f"holder = getattr(m, {owner!r}) if {owner!r} else m\n"
            f"orig = getattr(holder, {name!r})\n"
            f"def wrapped(*a, **k):\n"
            f"    if not {after!r}:\n"
            f"        os.kill(os.getpid(), signal.SIGKILL)\n"
            f"    out = orig(*a, **k)\n"
            f"    os.kill(os.getpid(), signal.SIGKILL)\n"
            f"setattr(holder, {name!r}, wrapped)\n"
            f"from campaign.cli import main\n"
            f"sys.exit(main())\n")


def secret_hits(root: Path, *texts: str, secret: str = SECRET, inputs: dict[str, str] | None = None) -> list[str]:
    """Where ``secret`` was written: the texts (stdout, stderr) or any file under ``root`` (crash reports too) but
    the ``inputs`` (path -> sha256 from :func:`checksums`) left as they were."""
    inputs = inputs or {}
    hits = [f"output {i}" for i, t in enumerate(texts) if secret in t]
    return hits + [path for path, digest in checksums(root).items()
                   if inputs.get(path) != digest and secret.encode() in Path(path).read_bytes()]
