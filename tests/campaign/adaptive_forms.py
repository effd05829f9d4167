"""The simulated campaigns of issue 32's selection protocol (``bench/bench_select.py --adaptive``) and of its seeded
test, unlike each other; each builder returns (dataset, cell) for one seed.

* Truth-simulator forms (``robocal.simulation.truth_cell``: an IRB 2600 written from the physics, its own code, 300
  calibration poses in random order over two hours with payload blocks of 0 / 12 kg, 100 test poses measured among
  them, 10 check poses x 5 repeats; read-back joints, times and payloads as a real log gives them).
* Config forms (``configs/*.yaml`` through ``campaign.config.simulation`` and ``helpers.simulated_campaign``: the
  cell's grid plan, made denser so that the pool holds 300+ poses, measured once; its test set measured separately).
"""
from __future__ import annotations

from pathlib import Path

import yaml

from campaign.config.load import load_cell
from campaign.data.source import load_source
from robocal.simulation.truth_cell import TruthProtocol, simulate

from .helpers import ROOT, simulated_campaign, truth_csv


def truth_form(effects, protocol: TruthProtocol = TruthProtocol(), scale: float | None = None):
    """A builder of truth-simulator campaigns with ``effects`` (their sizes drawn per seed unless ``scale``)."""
    def build(tmp: Path, seed: int):
        camp = simulate(effects, seed, protocol, scale)
        d = tmp / f"truth-{seed}-{'-'.join(effects)}"
        d.mkdir(parents=True, exist_ok=True)
        csv, cfg = truth_csv(d, camp)
        return load_source(csv).dataset, load_cell(cfg)
    return build


def config_form(cfg_name: str, effects: list, step_mm: float, test_count: int = 100):
    """A builder of a config's simulated cell (seeded truth geometry) with ``effects``, its grid every ``step_mm``."""
    def build(tmp: Path, seed: int):
        d = yaml.safe_load((ROOT / "configs" / cfg_name).read_text())
        d.setdefault("simulation", {}).update(seed=seed, effects=effects)
        d["plan"]["grid"]["step_mm"] = step_mm
        d["plan"]["test"]["count"] = test_count
        path = tmp / f"{Path(cfg_name).stem}-{seed}-{step_mm:g}.yaml"
        path.write_text(yaml.safe_dump(d, sort_keys=False))
        cell = load_cell(path)
        return simulated_campaign(cell, seed), cell
    return build


GEAR = [1.4e-4, 1.4e-4, 7.0e-5, 7.0e-5]
COMPLIANCE = {"name": "joint_compliance", "params": {"values": [1.0e-6, 2.0e-6]}}

# the simulated forms of issue 32's protocol (fixed with it; see bench_select.py)
ADAPTIVE_FORMS = {
    "compliance+gear+drift": truth_form(["joint_compliance", "gear_cyclic", "registration_drift"]),
    "strong compliance, sparse far": truth_form(["joint_compliance"], TruthProtocol(sampling="sparse_extremes"),
                                                scale=3.0),
    "read-back lag": truth_form(["readback_lag"]),
    "UR10-like (compliance + J2 gear)": config_form("ur10.yaml", [COMPLIANCE, {"name": "gear_cyclic", "params": {
        "joint": 2, "values": GEAR}}], 100.0),
    "IRB 4600-like (compliance + J3 gear + coupling)": config_form("irb4600.yaml", [COMPLIANCE, {
        "name": "gear_cyclic", "params": {"joint": 3, "values": GEAR}}, {"name": "axis_coupling", "params": {
            "values": [3e-4, 2e-4, 2e-4]}}], 150.0),
    "layer only (sag outside the library)": truth_form(["reach_deflection"]),
}
