"""``plan.kind: optimal``: the plan, its forecast, and the bad inputs that must stop before anything moves."""
from __future__ import annotations

import numpy as np
import pytest

from campaign.config.load import load_cell, load_config
from campaign.plan.build import build_plan
from robocal.design.optimal import move_cost
from tests.campaign.helpers import small_config
from tests.campaign.hostile import assert_one_line, cli, snapshot


POOL = {"plan.pool": {"step_mm": 200, "tilts": 2}}      # a small pool: fast


def _grid_config(tmp_path):
    (tmp_path / "g").mkdir(exist_ok=True)
    return small_config(tmp_path / "g")


def _config(tmp_path, **over):
    return small_config(tmp_path, **{**POOL, "plan.kind": "optimal", "plan.points": 60, **over})


@pytest.mark.system
def test_optimal_plan_chooses_points_from_the_pool_and_keeps_the_grid_test_set(tmp_path):
    plan = build_plan(load_cell(_config(tmp_path)))
    grid = build_plan(load_cell(_grid_config(tmp_path)))
    calib = [p for p in plan.points if p.set == "calib"]
    assert len(calib) == 60 and len({p.point_id for p in calib}) == 60
    tests = lambda pl: sorted((p.point_id, p.q_deg) for p in pl.points if p.set == "test")  # noqa: E731
    assert tests(plan) == tests(grid)                   # the held-out set is the grid plan's
    assert all(p.point_id.startswith("O") for p in calib)   # candidates of the pool (a resumed run rebuilds the
    #                                                    same plan: tests/campaign/calibrate/test_adaptive_stop.py)
    q = np.radians([p.q_deg for p in calib])
    toured = move_cost(q[:-1], q[1:]).sum()
    shuffled = q[np.random.default_rng(0).permutation(len(q))]
    assert toured < 0.6 * move_cost(shuffled[:-1], shuffled[1:]).sum()   # a short tour, no back-and-forth
    tilted = {p.point_id.split("-")[-1][0] for p in calib}
    assert len(tilted) > 1                              # orientations other than tool_direction were chosen


@pytest.mark.system
def test_stop_auto_plan_has_blocks_and_the_test_set_last(tmp_path):
    plan = build_plan(load_cell(_config(tmp_path, **{"plan.stop": "auto", "plan.points": 80,
                                                     "plan.block_points": 10})))
    sets = [p.set for p in plan.points if p.set in ("calib", "test")]
    assert sets == ["calib"] * 80 + ["test"] * sets.count("test")
    assert plan.blocks[-1] == 80 and list(plan.blocks) == sorted(plan.blocks) and len(plan.blocks) >= 3
    assert all(b - a == 10 for a, b in zip(plan.blocks[:-1], plan.blocks[1:-1]))


@pytest.mark.system
def test_campaign_plan_prints_the_forecast_for_grid_and_optimal_plans(tmp_path, capsys):
    for path in (_grid_config(tmp_path), _config(tmp_path)):
        code, out, err = cli(capsys, "plan", path)
        assert code == 0, err
        assert "predicted AP(theta) RMS at the test poses" in out and "largest std" in out
        assert "estimated duration" in out


@pytest.mark.system
@pytest.mark.parametrize("over, needles", [
    ({"plan.points": 5000}, ("plan.points", "5000", "candidate pool holds only")),
    ({"plan.points": 12}, ("plan.points", "12", "identifiable + 10 %")),
    ({"plan.keep_out": [{"name": "all", "min_mm": [-3000, -3000, -3000], "max_mm": [3000, 3000, 3000]}]},
     ("plan.keep_out", "keep-out")),
    ({"plan.stop": "auto", "plan.max_points": 9}, ("plan.max_points", "9")),
])
def test_bad_counts_and_an_emptied_pool_exit_2_before_anything_moves(tmp_path, capsys, over, needles):
    path = _config(tmp_path, **over)
    runs = tmp_path / "runs"
    before = snapshot(tmp_path)
    for command in ("plan", "run") if "plan.keep_out" in over else ("run",):
        code, out, err = cli(capsys, command, path)
        assert_one_line(code, out, err, 2, *needles)
    assert not runs.exists() and snapshot(tmp_path) == before


@pytest.mark.unit
def test_optimal_keys_are_checked_by_validate(tmp_path, capsys):
    for over, needle in (({"plan.points": None}, "plan.points"),
                         ({"plan.kind": "grid", "plan.stop": "auto"}, "plan.stop"),
                         ({"plan.pool": {"wrist_flip": "yes"}}, "plan.pool.wrist_flip"),
                         ({"plan.order": "random"}, "plan.order"),
                         ({"plan.pool": {"step_mm": 1}}, "plan.pool.step_mm")):
        code, out, err = cli(capsys, "validate", _config(tmp_path, **over))
        assert_one_line(code, out, err, 2, needle)


@pytest.mark.unit
def test_stop_rule_decisions(tmp_path):
    """The decision after a refit: the gain of the next block against stop_gain_pct % of the floor, the time
    budget, the last block."""
    from campaign.calibrate.adaptive_stop import _decide
    from campaign.plan.points import Plan
    from robocal.design.optimal import Prediction

    cfg = load_config(_config(tmp_path, **{"plan.stop": "auto", "plan.max_minutes": 30.0}))
    plan = Plan((), (), "x", (60, 80, 100))
    pred = lambda rms: Prediction(np.array(plan.blocks), np.array(rms), 0.03, 0.0, 1.0, 0.031)  # noqa: E731
    stop = _decide(cfg, plan, 60, pred([0.0330, 0.0327, 0.0326]), 600.0)     # gains 0.3 um < 0.6 um
    assert stop.decision == "stop" and "less than 2 % of the noise floor" in stop.reason
    assert stop.predicted_rms_mm == 0.0330 and stop.gain_next_mm == pytest.approx(0.0003)
    go = _decide(cfg, plan, 60, pred([0.0340, 0.0330, 0.0326]), 600.0)
    assert go.decision == "continue" and go.curve[0] == (60, 0.0340)
    late = _decide(cfg, plan, 80, pred([0.0340, 0.0330, 0.0326]), 28 * 60.0)  # 20 more points need ~7 min
    assert late.decision == "stop" and "max_minutes" in late.reason
    last = _decide(cfg, plan, 100, pred([0.0340, 0.0330, 0.0326]), 600.0)
    assert last.decision == "stop" and last.gain_next_mm is None
