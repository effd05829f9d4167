"""``plan.kind: adaptive``: the keys and their one-line errors, the plan (seed, candidates, test set last), the task,
the forecast ``campaign plan`` prints, and the motion safety of the poses the rounds add."""
from __future__ import annotations

import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.plan.adaptive import seed_rows, seed_size, task_poses
from campaign.plan.build import build_plan
from campaign.plan.motion_safety import PathGuard
from robocal.kinematics.models import smr_base
from robocal.kinematics.sweep import flange_points_base, sample_segments
from tests.campaign.helpers import small_config
from tests.campaign.hostile import assert_one_line, cli, snapshot

POOL = {"plan.pool": {"step_mm": 200, "tilts": 2}}
WALL = {"name": "fixture", "min_mm": [1000, -300, 500], "max_mm": [1200, 300, 800]}   # inside the grid box


def _config(tmp_path, **over):
    return small_config(tmp_path, **{**POOL, "plan.kind": "adaptive", "plan.max_points": 60, **over})


@pytest.mark.unit
@pytest.mark.parametrize("over, needle", [
    ({"plan.max_points": None}, "plan: plan.kind: adaptive needs its pose budget: plan.max_points"),
    ({"plan.points": 40}, "plan.points: an adaptive plan chooses its points as it measures"),
    ({"plan.order": "random"}, "plan.order: an adaptive plan is measured in a short tour"),
    ({"plan.task": {}}, "plan.task: give one of targets_csv"),
    ({"plan.task": {"targets_csv": "t.csv", "box_mm": [[0, 0, 0], [1, 1, 1]]}}, "plan.task: give one of"),
    ({"plan.task": {"box_mm": [[0, 0, 0], [1, 1]]}}, "plan.task.box_mm[1]: expected a list of 3 numbers"),
    ({"plan.task": {"box_mm": [[0, 0, 0], [1, 0, 1]]}}, "plan.task.box_mm: the two corners have the same y"),
    ({"plan.task": {"box": [[0, 0, 0], [1, 1, 1]]}}, "plan.task.box: unknown key"),
])
def test_adaptive_keys_are_checked_by_validate(tmp_path, capsys, over, needle):
    code, out, err = cli(capsys, "validate", _config(tmp_path, **over))
    assert_one_line(code, out, err, 2, needle)


@pytest.mark.system
def test_the_plan_holds_the_seed_the_candidates_and_the_test_set_last(tmp_path, capsys):
    path = _config(tmp_path, **{"plan.keep_out": [WALL]})
    cell = load_cell(path)
    plan = build_plan(cell)
    calib = [p for p in plan.points if p.set == "calib"]
    sets = [p.set for p in plan.points if p.set in ("calib", "test")]
    assert sets == ["calib"] * len(calib) + ["test"] * sets.count("test") and sets.count("test") > 0
    assert plan.blocks == (len(calib),) and len(calib) == seed_size(24, 60, 5) == 27   # IRB 2600: 24 geometric
    ids = {p.point_id for p in plan.candidates}
    assert {p.point_id for p in calib} <= ids and len(ids) == len(plan.candidates) > 300
    guard = PathGuard.for_cell(cell)                      # every candidate is a stop a plan may use
    q = np.array([p.q_deg for p in plan.candidates])
    assert all(r is None for r in guard.pose_reasons(q))
    kin = cell.kinematics
    assert np.all((np.radians(q) >= kin.q_min_rad) & (np.radians(q) <= kin.q_max_rad))
    code, out, err = cli(capsys, "plan", path, "--csv", tmp_path / "plan.csv")
    assert code == 0, err
    assert "Forecast learning curve" in out and "the full grid" in out and "whole pose budget" in out
    rows = (tmp_path / "plan.csv").read_text().splitlines()
    assert sum(",candidate," in r for r in rows) == len(plan.candidates)


@pytest.mark.system
def test_the_forecast_takes_the_poses_in_the_order_the_rounds_will(tmp_path):
    """Under rule ``f`` the rounds continue the seed farthest-first in lever-scaled joint space: the forecast's
    order is the seed, then that continuation up to the pose budget."""
    from campaign.plan.adaptive import RULE
    from campaign.plan.learning import plan_order
    from campaign.plan.optimal import tracker_kinematics
    from robocal.design import lever_scaled

    assert RULE == "f"
    cell = load_cell(_config(tmp_path, **{"plan.max_points": 40}))
    plan = build_plan(cell)
    n0 = sum(p.set == "calib" for p in plan.points)
    order = plan_order(cell, plan)
    qc = np.radians([p.q_deg for p in plan.candidates])
    kin_t = tracker_kinematics(cell)
    X = lever_scaled(kin_t, qc)
    assert len(order) == 40 and len({tuple(np.round(q, 9)) for q in order}) == 40
    for k in (n0, n0 + 1, 39):                                # each the farthest from every pose before it
        gap = np.min(np.linalg.norm(X[:, None] - lever_scaled(kin_t, order[:k], qc)[None], axis=2), axis=1)
        assert np.allclose(order[k], qc[np.argmax(gap)])


@pytest.mark.system
def test_with_a_task_the_forecast_and_the_rounds_pick_the_task_first(tmp_path, capsys):
    """With ``plan.task`` rule ``f``'s picks cover the task (``covered_task``): after the seed, the forecast's order
    and the first round of a mock run take candidates inside the task box, where without a task they spread."""
    from campaign.plan.learning import plan_order
    from campaign.calibrate.adaptive_rounds import round_checks
    from campaign.run.log_reader import read_log

    box = {"box_mm": [[900, -400, 600], [1300, 400, 1000]]}
    lo, hi = np.array(box["box_mm"][0]) - 0.01, np.array(box["box_mm"][1]) + 0.01   # grid poses on its faces
    in_box = lambda q: np.all((lo <= smr_base(cell.kinematics, q)) & (smr_base(cell.kinematics, q) <= hi), 1)  # noqa: E731
    shares = {}
    for task in (None, box):
        d = tmp_path / ("task" if task else "none")
        d.mkdir()
        path = small_config(d, **{**POOL, "plan.kind": "adaptive", "plan.max_points": 37,
                                  **({"plan.task": task} if task else {})})
        cell = load_cell(path)
        plan = build_plan(cell)
        n0 = sum(p.set == "calib" for p in plan.points)
        shares[task is not None] = float(np.mean(in_box(plan_order(cell, plan)[n0:n0 + 10])))
    assert shares[True] == 1.0 and shares[False] < 0.5, shares
    code, _, err = cli(capsys, "run", path, "--out", d / "run")               # the last: with the task
    assert code == 0, err
    added = [r for r in round_checks(read_log(d / "run")) if r.decision == "continue"][0].added
    q = {c.point_id: c.q_deg for c in plan.candidates}
    assert len(added) == 10 and np.all(in_box(np.radians([q[i] for i in added])))


@pytest.mark.system
def test_task_box_and_targets_give_the_task_poses(tmp_path):
    box = {"box_mm": [[900, -400, 600], [1300, 400, 1000]]}
    cell = load_cell(_config(tmp_path, **{"plan.task": box}))
    plan = build_plan(cell)
    q = np.radians([p.q_deg for p in plan.candidates])
    p = np.array([c.p_base_mm for c in plan.candidates])
    task = task_poses(cell, q, p)
    inside = smr_base(cell.kinematics, task)
    assert 0 < len(task) < len(q)
    assert np.all((inside > np.array(box["box_mm"][0]) - 150) & (inside < np.array(box["box_mm"][1]) + 150))
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "targets.csv").write_text("target_id,x,y,z\nA,1100,0,800\nB,1100,200,900\nfar,9000,0,0\n")
    cell = load_cell(small_config(tmp_path / "t", **{**POOL, "plan.kind": "adaptive", "plan.max_points": 60,
                                                     "plan.task": {"targets_csv": "targets.csv"}}))
    task = task_poses(cell, q, p)
    assert len(task) == 2                                 # the unreachable target is left out
    np.testing.assert_allclose(smr_base(cell.kinematics, task)[:, :3][0], [1100, 0, 800], atol=0.5)


@pytest.mark.system
def test_bad_budget_and_task_exit_2_before_anything_moves(tmp_path, capsys):
    for over, needles in (({"plan.max_points": 12}, ("plan.max_points", "identifiable + 10 %")),
                          ({"plan.max_points": 9999}, ("plan.max_points", "candidate pool holds only")),
                          ({"plan.task": {"targets_csv": "missing.csv"}}, ("plan.task.targets_csv", "cannot read"))):
        path = _config(tmp_path, **over)
        before = snapshot(tmp_path)
        code, out, err = cli(capsys, "run", path)
        assert_one_line(code, out, err, 2, *needles)
        assert snapshot(tmp_path) == before


@pytest.mark.system
def test_every_move_of_an_adaptive_run_stays_clear_of_the_keep_out_box(tmp_path, monkeypatch):
    """The rounds' poses come from the checked candidates and every move goes through the guard: an independent
    fine sampling of the commanded joint path (vias included) finds the flange and SMR clear of the box."""
    from drivers.mock import MockRobot
    from campaign.workflows import run_campaign

    cell = load_cell(_config(tmp_path, **{"plan.keep_out": [WALL], "plan.max_points": 50}))
    path = []
    real = MockRobot.move_joints
    monkeypatch.setattr(MockRobot, "move_joints", lambda self, q: (path.append(np.asarray(q, float)), real(self, q)))
    result = run_campaign(cell, tmp_path / "run")
    assert result.outcome.exit_status == "success"
    rounds = [e for e in __import__("campaign.run.log_reader", fromlist=["read_log"]).read_log(tmp_path / "run").events
              if e["type"] == "adaptive_round" and e["decision"] == "continue"]
    assert rounds, "at least one round added poses"
    q = np.radians(np.array(path))
    fine, _ = sample_segments(q[:-1], q[1:], np.full(len(q) - 1, 200))
    guard = PathGuard.for_cell(cell)
    pts = flange_points_base(cell.kinematics, fine, guard.p_flange_points_mm).reshape(-1, 3)
    box = guard.keep_out.grown(cell.config.plan.clearance_mm - 1e-6)
    inside = np.all((pts[:, None] > box.lo) & (pts[:, None] < box.hi), axis=-1).any(axis=1)
    assert not inside.any()


@pytest.mark.system
def test_the_seed_is_spread_wider_than_a_d_optimal_one_and_determines_the_geometry():
    """The campaign's seed (chosen by ``bench/bench_select.py --adaptive``, the revised protocol of issue 32):
    farthest-first in lever-scaled joint space, its closest pair farther apart than in the D-optimal seed of the
    same size, and every identifiable geometric parameter still determined."""
    from scipy.spatial.distance import pdist

    from robocal.design.optimal import criterion, space_filling
    from tests.cells import irb2600, irb2600_poses

    kin = irb2600()
    qc, _ = irb2600_poses()
    c = criterion(kin, qc, np.broadcast_to(np.eye(3) * 1e-3, (len(qc), 3, 3)))
    n = seed_size(c.identifiable_geometric, 100, 5)
    seed, d_seed = seed_rows(kin, c, qc, n), seed_rows(kin, c, qc, n, "d_optimal")
    closest = lambda idx: pdist(qc[idx] * c.levers_mm_per_rad).min()     # noqa: E731
    assert closest(seed) > 1.5 * closest(d_seed)
    chosen, determined = space_filling(kin, c, qc, n)
    assert determined and np.array_equal(seed, chosen)
    with pytest.raises(ValueError, match="unknown seed design"):
        seed_rows(kin, c, qc, n, "random")
