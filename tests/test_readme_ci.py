"""The README's test command is the one CI runs (environment variables included)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands() -> list[str]:
    block = re.search(r"```\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    return [line.strip() for line in block.group(1).splitlines() if line.strip()]


@pytest.mark.unit
def test_readme_starts_with_two_setup_commands_and_ci_runs_the_second():
    commands = _readme_commands()
    assert len(commands) == 2, commands
    assert "campaign run configs/" in commands[0]
    ci_lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert commands[1] in ci_lines, f"{commands[1]!r} is not a line of .ci/run"
    assert "pytest" in commands[1] and "OPENBLAS_NUM_THREADS=1" in commands[1]
