"""The early size check (campaign/data/memory_check.py): data that needs more memory than the machine allows stops
the command with one line saying how many rows fit and what to do, before anything is read."""
from __future__ import annotations

import resource
import subprocess
import sys

import pytest

from campaign.cli import main
from campaign.data import memory_check
from campaign.data.memory_check import CALIBRATE, CV_MAX_ROWS, SELECT
from tests.campaign.helpers import ROOT


@pytest.mark.unit
@pytest.mark.parametrize("need", [CALIBRATE, SELECT])
def test_the_rows_that_fit_are_the_most_whose_need_stays_within_the_budget(need):
    for rows in (0, 1, 999, CV_MAX_ROWS - 1, CV_MAX_ROWS, CV_MAX_ROWS + 1, 3 * CV_MAX_ROWS, 10_000_000):
        budget = need.bytes(rows)
        assert need.rows_within(budget) == rows
        if rows:
            assert need.rows_within(budget - 1) == rows - 1
    assert need.rows_within(need.base_bytes - 1) == 0


def _csv(tmp_path, rows):
    """A data file of ``rows`` lines (the check counts lines before anything is read or parsed)."""
    path = tmp_path / "big.csv"
    path.write_text("point_id,set,q1,q2,q3,q4,q5,q6,x,y,z\n" + "P,calib,0,0,0,0,0,0,0,0,0\n" * (rows - 1))
    return path


@pytest.mark.system
@pytest.mark.parametrize("command", ["reprocess", "diagnose", "select"])
def test_data_too_large_for_the_memory_stops_early_with_one_line(tmp_path, monkeypatch, capsys, command):
    csv = _csv(tmp_path, 5000)
    need = SELECT if command == "select" else CALIBRATE
    fits = 1200
    monkeypatch.setattr(memory_check, "available_bytes", lambda: (need.bytes(fits), "available memory"))
    config = str(ROOT / "configs" / "irb2600.yaml")
    out = {"reprocess": ["--out", str(tmp_path / "out")], "diagnose": ["--json", str(tmp_path / "d.json")],
           "select": ["--points", "100", "--out", str(tmp_path / "sub.csv")]}[command]
    assert main([command, str(csv), "--config", config, *out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"error: {csv}: 5000 rows need about ") and f"at most {fits} rows fit" in err[0]
    assert ("campaign select" in err[0]) == (command != "select")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.csv"]        # nothing written


@pytest.mark.system
def test_under_a_real_address_space_limit_the_command_stops_before_reading(tmp_path):
    """No patch: ``diagnose`` of 300 000 rows in a child limited to 1 GiB of address space (``ulimit -v``) stops at
    the check with one line naming that limit, exit 2 (read, the rows would end in a MemoryError or another error)."""
    csv = _csv(tmp_path, 300_000)

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))

    proc = subprocess.run([sys.executable, "-m", "campaign", "diagnose", str(csv), "--config",
                           str(ROOT / "configs" / "irb2600.yaml"), "--json", str(tmp_path / "d.json")],
                          cwd=ROOT, capture_output=True, text=True, preexec_fn=limit, timeout=120)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1, proc.stderr
    assert err[0].startswith(f"error: {csv}: 300000 rows need about ") and "the address-space limit" in err[0]
    fit = int(err[0].split("at most ")[1].split()[0])
    assert 0 < fit < 300_000 and not (tmp_path / "d.json").exists()
