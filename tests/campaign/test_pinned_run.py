"""The figures of one small mock run of the demo cell are pinned (rel 1e-7, room only for BLAS rounding across
CPUs): a refactor that changes any of them fails here.

Regenerate deliberately (a numerical change that is meant) with:
``PIN_UPDATE=1 OPENBLAS_NUM_THREADS=1 python3 -m pytest tests/campaign/test_pinned_run.py``
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from campaign.cli import main
from tests.campaign.helpers import small_config

PIN = Path(__file__).resolve().parents[1] / "data" / "pinned_irb2600_small.json"


def _figures(report: dict) -> dict:
    """The numbers a user reads: counts, every stage's statistics, noise floor, identified parameters (the exported
    model's, and the geometry-only fit's beside them)."""
    return {
        "n": report["n"],
        "stages": {s: {k: v for k, v in rows.items() if k in ("test", "calib")}
                   for s, rows in report["stages"].items()},
        "noise_floor_mm": report["noise_floor_mm"],
        "noise_floor_source": report["noise_floor_source"],
        "parameters": {p["name"]: [p["delta"], p["std"]] for p in report["parameters"]},
        "parameters_geometry_only": {p["name"]: [p["delta"], p["std"]] for p in report["parameters_geometry_only"]},
        "T_tracker_base": report["T_tracker_base"],
    }


def _close(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a for d in _close(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _close(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
        return [] if math.isclose(a, b, rel_tol=1e-7, abs_tol=1e-10) else [f"{path}: {a!r} != pinned {b!r}"]
    return [] if a == b else [f"{path}: {a!r} != pinned {b!r}"]


@pytest.mark.system
def test_mock_run_figures_are_pinned(tmp_path):
    cfg = small_config(tmp_path, "irb2600", phenomena=True)      # the demo cell, its real-cell phenomena on
    assert main(["run", str(cfg), "--out", str(tmp_path / "run")]) == 0
    got = _figures(json.loads((tmp_path / "run" / "report.json").read_text()))
    if os.environ.get("PIN_UPDATE"):
        PIN.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
    pinned = json.loads(PIN.read_text())
    diffs = _close(json.loads(json.dumps(got)), pinned)
    assert not diffs, "figures moved: " + "; ".join(diffs[:8])
