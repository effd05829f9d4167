"""Multi-SMR tool (seed 003): tool.p_flange_smr2_mm / p_flange_smr3_mm in the config, and the mock tracker +
runner logging the second and third SMR at every stop."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from campaign.config.simulation import simulated_cell
from campaign.cli import main
from campaign.config.load import load_cell, load_config
from campaign.errors import ConfigError
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.data.log_dataset import dataset_from_log
from campaign.plan.build import build_plan
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log
from campaign.run.runner import Runner
from drivers.base import DriverError, TargetNotFound
from drivers.mock import MockRobot, MockTracker, MockWorld
from tests.campaign.helpers import ROOT, small_config

pytestmark = pytest.mark.unit

CONFIGS = ROOT / "configs"
SMR2 = [72.676, -65.854, 80.0]          # seed 003 Table 4 triangle (d12 = 144.833 mm, d13, d23 ~ 210 mm)
SMR3 = [-0.518, 131.707, 80.0]
SMR1 = [-72.157, -65.854, 80.0]


def write(tmp_path: Path, tool: dict[str, Any], name: str = "irb4600") -> Path:
    doc = yaml.safe_load((CONFIGS / f"{name}.yaml").read_text(encoding="utf-8"))
    doc["tool"].update(tool)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


# --------------------------------------------------------------------------- config keys


@pytest.mark.parametrize("name", ["irb2600.yaml", "ur10.yaml", "irb4600.yaml"])
def test_shipped_configs_have_one_smr(name: str) -> None:
    tool = load_config(CONFIGS / name).tool
    assert tool.p_flange_smr2_mm is None and tool.p_flange_smr3_mm is None
    assert tool.smrs_mm == (tool.p_flange_smr_mm,)


def test_three_smrs_are_read_as_float_tuples(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, {"p_flange_smr_mm": SMR1, "p_flange_smr2_mm": SMR2, "p_flange_smr3_mm": SMR3}))
    assert cfg.tool.p_flange_smr2_mm == tuple(float(v) for v in SMR2)
    assert all(isinstance(v, float) for v in cfg.tool.p_flange_smr3_mm)
    assert cfg.tool.smrs_mm == (tuple(SMR1), tuple(SMR2), tuple(SMR3))


def test_two_smrs_and_null_keys(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, {"p_flange_smr2_mm": SMR2, "p_flange_smr3_mm": None}))
    assert cfg.tool.p_flange_smr3_mm is None and len(cfg.tool.smrs_mm) == 2


def test_to_dict_reloads_to_the_same_config(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, {"p_flange_smr_mm": SMR1, "p_flange_smr2_mm": SMR2, "p_flange_smr3_mm": SMR3}))
    plain = json.loads(json.dumps(cfg.to_dict()))
    assert plain["tool"]["p_flange_smr3_mm"] == SMR3
    del plain["sha256"], plain["source_path"]
    again = tmp_path / "again.yaml"
    again.write_text(yaml.safe_dump(plain), encoding="utf-8")
    reloaded = load_config(again)
    assert dataclasses.replace(reloaded, source_path=cfg.source_path, sha256=cfg.sha256) == cfg


BAD = {
    "third_without_second": ({"p_flange_smr3_mm": SMR3},
                             "tool.p_flange_smr3_mm: a third SMR needs p_flange_smr2_mm (the second SMR)"),
    "two_numbers": ({"p_flange_smr2_mm": [1.0, 2.0]}, "tool.p_flange_smr2_mm: expected a list of 3 numbers, got 2"),
    "text_coordinate": ({"p_flange_smr2_mm": [1.0, "x", 3.0]}, "tool.p_flange_smr2_mm[1]: expected a number, got 'x'"),
    "overlapping_balls": ({"p_flange_smr2_mm": [10.0, 0.0, 39.4]},
                          "tool.p_flange_smr2_mm: SMR centre 10.0 mm from p_flange_smr_mm: closer than one ball "
                          "(smr_diameter_mm = 38.1)"),
    "third_on_second": ({"p_flange_smr2_mm": SMR2, "p_flange_smr3_mm": [70.0, -60.0, 80.0]},
                        "tool.p_flange_smr3_mm: SMR centre 6.4 mm from p_flange_smr2_mm"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_smr_keys_raise_one_line_errors(tmp_path: Path, case: str) -> None:
    tool, expect = BAD[case]
    path = write(tmp_path, tool)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    assert expect in message, message


def test_bad_smr_key_cli_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, BAD["third_without_second"][0])
    assert main(["validate", str(path)]) == 2
    _, err = capsys.readouterr()
    assert len(err.strip().splitlines()) == 1 and "tool.p_flange_smr3_mm" in err


# --------------------------------------------------------------------------- mock tracker + runner


def multi_smr_run(tmp_path: Path, n_smrs: int = 3):
    """Five plan points of a small IRB 4600 cell with a three-SMR tool, measured by the mock drivers."""
    path = small_config(tmp_path, "irb4600", **{"tool.p_flange_smr_mm": SMR1, "tool.p_flange_smr2_mm": SMR2,
                                                 "tool.p_flange_smr3_mm": SMR3, "simulation.p_flange_smr_mm": SMR1})
    cell = load_cell(path)
    cfg = cell.config
    world = MockWorld(simulated_cell(cell), cfg.simulation.seed, q0_deg=cfg.plan.q_ref_deg,
                      extra_smrs_flange_mm=cfg.tool.smrs_mm[1:])
    points = build_plan(cell).points[:5]
    log = RunLog.create(tmp_path / "run", {"config_sha256": cfg.sha256, "plan_sha256": "x"})
    runner = Runner(MockRobot(world), MockTracker(world), cfg.tracker.measurement, world.clock,
                    lambda p: cell.covariance(p[None])[0], n_smrs=n_smrs)
    truth = []
    runner.on_point = lambda point, record: truth.append(
        [c.true_smr_tracker(np.radians(world.q_deg)[None])[0] for c in (world.cell, *world.extra_cells)])
    outcome = runner.execute(points, log)
    return cfg, outcome, read_log(tmp_path / "run"), np.array(truth)


def test_runner_logs_the_second_and_third_smr(tmp_path: Path) -> None:
    cfg, outcome, log, truth = multi_smr_run(tmp_path)
    assert outcome.exit_status == "success" and len(log.points) == 5
    rec = log.points[0]
    for key in ("p_tracker_mm", "p2_tracker_mm", "p3_tracker_mm", "cov2_mm2", "cov3_mm2", "retries2", "spread3_mm"):
        assert key in rec
    assert [r.to_dict() for r in log.records()] == log.points        # the typed records are exactly what was logged
    ds = dataset_from_log(log)
    meas = np.stack([ds.p_tracker_mm, ds.p2_tracker_mm, ds.p3_tracker_mm], axis=1)
    assert np.max(np.linalg.norm(meas - truth, axis=2)) < 0.25            # tracker noise + repeatability
    d = np.linalg.norm(meas[:, [0, 0, 1]] - meas[:, [1, 2, 2]], axis=2)
    np.testing.assert_allclose(d, np.broadcast_to([144.833, 210.149, 210.684], d.shape), atol=0.1)
    write_csv(tmp_path / "data.csv", ds)
    header = (tmp_path / "data.csv").read_text().splitlines()[0]
    assert "x2" in header and "z3" in header
    np.testing.assert_array_equal(read_csv(tmp_path / "data.csv").p3_tracker_mm, ds.p3_tracker_mm)


def test_single_smr_runs_log_no_extra_keys(tmp_path: Path) -> None:
    _, outcome, log, _ = multi_smr_run(tmp_path, n_smrs=1)
    assert outcome.exit_status == "success"
    assert not any(k.startswith(("p2_", "p3_", "cov2", "cov3")) for k in log.points[0])
    assert dataset_from_log(log).p2_tracker_mm is None


def test_trackers_without_smr_selection_are_refused_up_front(tmp_path: Path) -> None:
    class OneTarget:
        url = "stub://tracker"

        def measure(self): ...

    with pytest.raises(DriverError, match="stub://tracker: the tool has 3 SMRs"):
        Runner(None, OneTarget(), None, None, lambda p: np.eye(3), n_smrs=3)
    cell = load_cell(small_config(tmp_path, "irb4600"))
    tracker = MockTracker(MockWorld(simulated_cell(cell), 0, extra_smrs_flange_mm=[SMR2]))
    tracker.select_smr(2)
    with pytest.raises(TargetNotFound, match="no SMR 3 on the tool"):
        tracker.select_smr(3)
