"""Shared machinery of the hostile-input tables (issue 12): run the CLI in-process, check the one-line contract,
snapshot directories to prove nothing was written or modified."""
from __future__ import annotations

import hashlib
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
