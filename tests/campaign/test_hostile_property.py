"""Property test (issue 12): 500 randomly mutated valid configs (seeded). Each one either fails ``validate``
with exit 2 and one line, or ``plan`` and a 5-point mock ``run`` complete (or stop with a device, data or
plausibility reason: exit 1 or 2, one line). Never a traceback, never exit 3, and the slowest case is printed."""
from __future__ import annotations

import copy
import math
import time

import numpy as np
import pytest
import yaml

from tests.campaign.helpers import ROOT, geometric_only
from tests.campaign.hostile import cli

N_CONFIGS = 500
SEED = 20261123


def five_point_config() -> dict:
    """The IRB 2600 reference with a 2 x 2 x 1 grid and one test point: a 5-point mock run (geometric-only truth,
    no nests)."""
    doc = geometric_only(yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text()))
    doc.pop("acceptance", None)                 # the demo's criterion is for its full plan, not one test point
    doc["plan"]["grid"] = {"center_mm": [900, 0, 1000], "size_mm": [400, 400, 1], "step_mm": 400}
    doc["plan"]["test"] = {"count": 1, "seed": 0}
    doc["plan"]["check_poses"] = {"count": 0, "every_n_points": 50}
    return doc


def leaves(node, path=()):
    """Every (path, value) of a nested dict/list, containers included."""
    yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from leaves(v, path + (i,))


WEIRD = [None, "", "abc", "1e-6", True, -1, 0, 1, 7, 10**12, -1e300, 1e300, math.nan, math.inf, 1e-300, [], {},
         [1, 2], {"x": 1}, "mock://robot", "tracker+socket://localhost", "abb-rws://", "x" * 200, -0.0, 0.5]


def mutate(doc: dict, rng: np.random.Generator) -> dict:
    """1 or 2 random mutations: replace a value, scale a number, delete a key, add an unknown key, or grow a list."""
    doc = copy.deepcopy(doc)
    for _ in range(int(rng.integers(1, 3))):
        paths = [p for p, _ in leaves(doc) if p]
        path = paths[int(rng.integers(len(paths)))]
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        key, value = path[-1], parent[path[-1]]
        op = int(rng.integers(5))
        if op == 0:
            parent[key] = WEIRD[int(rng.integers(len(WEIRD)))]
        elif op == 1 and isinstance(value, (int, float)) and not isinstance(value, bool):
            factor = float(rng.choice([-1.0, 0.0, 1e-3, 0.5, 2.0, 10.0, 1e3, 1e9]))
            parent[key] = type(value)(value * factor) if isinstance(value, int) else value * factor
        elif op == 2 and isinstance(parent, dict):
            del parent[key]
        elif op == 3 and isinstance(parent, dict):
            parent[f"unknown_{int(rng.integers(100))}"] = 1
        elif isinstance(value, list) and value:
            parent[key] = value + value[:1]
        else:
            parent[key] = WEIRD[int(rng.integers(len(WEIRD)))]
    return doc


def _check(code: int, out: str, err: str, allowed: set[int]) -> None:
    assert "Traceback" not in out + err and 'File "' not in out + err, (out + err)[-1500:]
    assert code in allowed, f"exit {code}: {err.strip()[:400]}"
    if code != 0:
        assert len(err.strip().splitlines()) == 1, err[:800]


@pytest.mark.system
def test_500_mutated_configs(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(SEED)
    base = five_point_config()
    base["output"] = {"dir": str(tmp_path / "runs")}
    counts = {"invalid": 0, "ran": 0, "measured_then_refused": 0, "run_stopped": 0}
    reasons: dict[str, int] = {}
    slowest = (0.0, -1)
    for i in range(N_CONFIGS):
        doc = mutate(base, rng)
        path = tmp_path / f"m{i:03d}.yaml"
        try:
            path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True), encoding="utf-8")
        except (yaml.YAMLError, ValueError, OverflowError):
            continue
        t0 = time.perf_counter()
        code, out, err = cli(capsys, "validate", path)
        _check(code, out, err, {0, 2})
        if code == 2:
            counts["invalid"] += 1
        else:
            code, out, err = cli(capsys, "plan", path)
            _check(code, out, err, {0})                     # whatever validate accepts, plan accepts
            code, out, err = cli(capsys, "run", path, "--out", tmp_path / f"run{i:03d}")
            _check(code, out, err, {0, 1, 2})               # complete, or a device / data / plausibility stop
            stop = _stop_status(tmp_path / f"run{i:03d}")
            counts["ran" if code == 0 else "measured_then_refused" if stop == "success" else "run_stopped"] += 1
            if code:
                reasons[err.split(":")[-1].strip()[:50]] = reasons.get(err.split(":")[-1].strip()[:50], 0) + 1
        slowest = max(slowest, (time.perf_counter() - t0, i))
    print(f"{N_CONFIGS} mutated configs: {counts}; slowest case #{slowest[1]} {slowest[0]:.2f} s; "
          f"run stop reasons {reasons}")
    assert counts["invalid"] > 50 and sum(counts.values()) - counts["invalid"] > 50   # both branches exercised
    assert counts["measured_then_refused"] + counts["ran"] > 30       # 5-point runs measured every point


def _stop_status(run_dir) -> str | None:
    """exit_status of the run log's last stop record (None without a log or a stop)."""
    from campaign.run.log_reader import read_log

    try:
        stops = read_log(run_dir).stops
    except (OSError, ValueError):
        return None
    return stops[-1]["exit_status"] if stops else None
