"""The README's test command is the whole set-up and the one CI runs: ``tests/run`` (a line of ``.ci/run``) gets
Chromium or stops with one line, installs the test dependencies, and runs pytest with the browser required. The
script is run here with stub commands on PATH (``id``, ``apt-get``, ``chromium``, ``python3``), so nothing is
installed and no suite starts."""
from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYTEST = "OPENBLAS_NUM_THREADS=1 python3 -m pytest -q -p no:cacheprovider -n auto"


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
    assert not [ln for ln in ci_lines if ln and not ln.startswith(("#", "set ", "cd ")) and ln != commands[1]], \
        ".ci/run runs something besides the README's test command"
    script = ROOT / commands[1]
    assert script.is_file() and os.access(script, os.X_OK), f"{commands[1]} is not an executable of the project"
    lines = [ln.strip() for ln in script.read_text().splitlines()]
    assert f'{PYTEST} "$@"' in lines and "python3 -m pip install -q -e '.[test]'" in lines


def _stub(bin_dir: Path, name: str, body: str) -> None:
    path = bin_dir / name
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


def _run_script(tmp_path: Path, uid: int, chromium: bool, apt_get: bool) -> tuple[subprocess.CompletedProcess, Path]:
    """tests/run with only stubs on PATH: ``id -u`` prints ``uid``; ``apt-get install`` creates a chromium stub;
    ``python3`` records its arguments and the two variables it must get."""
    bin_dir, calls = tmp_path / "bin", tmp_path / "calls"
    bin_dir.mkdir()
    _stub(bin_dir, "id", f"echo {uid}")
    _stub(bin_dir, "python3", f'echo "python3 $* OPENBLAS=$OPENBLAS_NUM_THREADS BROWSER=$CAMPAIGN_TESTS_BROWSER" '
                              f'>> "{calls}"')
    if chromium:
        _stub(bin_dir, "chromium", "exit 0")
    if apt_get:
        _stub(bin_dir, "apt-get", f'echo "apt-get $*" >> "{calls}"; case "$*" in *install*chromium*) '
                                  f'printf "#!/bin/sh\\n" > "{bin_dir}/chromium"; chmod +x "{bin_dir}/chromium";; esac')
    env = {"PATH": str(bin_dir), "HOME": str(tmp_path)}
    proc = subprocess.run(["/bin/bash", str(ROOT / "tests" / "run"), "-x"], env=env, capture_output=True, text=True,
                          timeout=60)
    return proc, calls


@pytest.mark.system
def test_without_chromium_and_no_way_to_install_it_one_line_and_nothing_runs(tmp_path):
    proc, calls = _run_script(tmp_path, uid=1000, chromium=False, apt_get=True)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Chromium is missing" in lines[0] and "apt-get install chromium" in lines[0], lines
    assert not calls.exists()                       # neither apt-get (not root) nor pip nor pytest ran


@pytest.mark.system
def test_as_root_it_installs_chromium_then_the_project_then_runs_pytest_with_the_browser_required(tmp_path):
    proc, calls = _run_script(tmp_path, uid=0, chromium=False, apt_get=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""   # quiet
    got = calls.read_text().splitlines()
    assert got[0] == "apt-get update -qq" and got[1] == "apt-get install -y -qq chromium", got
    assert got[2].startswith("python3 -m pip install -q -e .[test]")
    assert got[3] == "python3 -m pytest -q -p no:cacheprovider -n auto -x OPENBLAS=1 BROWSER=required", got


@pytest.mark.system
def test_with_chromium_present_nothing_is_installed_from_debian(tmp_path):
    proc, calls = _run_script(tmp_path, uid=0, chromium=True, apt_get=True)
    assert proc.returncode == 0, proc.stderr
    assert [c.split()[2] for c in calls.read_text().splitlines()] == ["pip", "pytest"]


@pytest.mark.system
def test_a_browser_test_is_required_under_tests_run_and_optional_elsewhere(tmp_path):
    """Without Chromium on PATH, the browser tests' skip condition holds only when tests/run did not ask for them."""
    code = "from tests.campaign.report.test_html import needs_browser; print(needs_browser.mark.args[0])"
    base = {"PATH": str(tmp_path), "PYTHONPATH": str(ROOT), "HOME": str(tmp_path)}
    for env, skipped in (({}, "True"), ({"CAMPAIGN_TESTS_BROWSER": "required"}, "False")):
        proc = subprocess.run([sys.executable, "-c", code], env={**base, **env}, cwd=ROOT, capture_output=True,
                              text=True, timeout=120)
        assert proc.stdout.strip() == skipped, proc.stderr[-2000:]
