"""Small configs derived from the shipped ones, for fast campaign tests."""
from __future__ import annotations

from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def small_config(tmp_path: Path, name: str = "irb2600", **overrides) -> Path:
    """Copy configs/NAME.yaml with a coarser grid (fast) and apply dotted-key overrides."""
    doc = yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())
    doc["plan"]["grid"]["step_mm"] = 400
    doc["plan"]["test"]["count"] = 30
    doc["plan"]["check_poses"] = {"count": 3, "every_n_points": 20}
    doc["output"] = {"dir": str(tmp_path / "runs")}
    for key, value in overrides.items():
        node = doc
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    path = tmp_path / f"{name}-small.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
