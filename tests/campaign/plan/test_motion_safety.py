"""Motion safety: speed caps reach the mock controller and bound every command; a cap above the datasheet is
refused; keep-out boxes and the envelope hold along the swept path of random plans (property test)."""
import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.errors import ConfigError
from campaign.plan.motion_safety import PathGuard, UnsafeMotion, motion_limits, payload, plan_route
from campaign.run.devices import mock_world
from campaign.plan.build import build_plan
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log
from campaign.run.runner import Runner
from drivers.base import MotionError, MotionLimits
from drivers.mock import MockRobot, MockTracker
from robocal.kinematics.sweep import Boxes, check_segments, flange_points_base, sample_segments
from tests.campaign.helpers import small_config


def _cell(tmp_path, **over):
    base = {"plan.grid.step_mm": 600, "plan.test.count": 6, "plan.check_poses": {"count": 0, "every_n_points": 50},
            "tracker.measurement.samples": 1, "tracker.measurement.settle_s": 0.0}
    return load_cell(small_config(tmp_path, **{**base, **over}))


def _mock_run(tmp_path, cell, robot_hook=None):
    cfg = cell.config
    world = mock_world(cell)
    robot, tracker = MockRobot(world), MockTracker(world)
    if robot_hook:
        robot_hook(robot)
    plan = build_plan(cell)
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x", "plan_sha256": plan.sha256})
    runner = Runner(robot, tracker, cfg.tracker.measurement, world.clock, lambda p: cell.covariance(p[None])[0],
                    limits=motion_limits(cfg), payload=payload(cfg))
    stops = []
    real_stop = robot.stop
    robot.stop = lambda: (stops.append(1), real_stop())
    return runner.execute(plan.points, log), robot, stops, plan


@pytest.mark.system
def test_no_command_above_the_caps_reaches_the_mock_controller(tmp_path):
    cell = _cell(tmp_path, **{"robot.max_tcp_speed_mm_s": 120, "robot.max_joint_speed_pct": 40})
    outcome, robot, stops, plan = _mock_run(tmp_path, cell)
    assert outcome.exit_status == "success" and stops == [1]
    peak = np.array([c.peak_tcp_mm_s for c in robot.commands])
    pct = np.array([c.joint_speed_pct for c in robot.commands])
    assert len(robot.commands) == len(plan.points)
    assert peak.max() <= 120 * (1 + 1e-9) and pct.max() <= 40 * (1 + 1e-9)
    assert peak.max() > 0.99 * 120                          # the cap binds: moves are slowed to it, not below
    print(f"commands {len(peak)}: peak TCP max {peak.max():.1f} mm/s (cap 120), joint max {pct.max():.1f} % (cap 40)")


@pytest.mark.system
def test_a_too_fast_command_is_refused_and_the_run_stops(tmp_path):
    cell = _cell(tmp_path)

    def too_fast(robot):
        real = robot.move_duration_s
        robot.move_duration_s = lambda a, b: 0.5 * real(a, b)      # a driver bug: twice the allowed speed
    outcome, robot, stops, _ = _mock_run(tmp_path, cell, too_fast)
    assert outcome.exit_status == "fail" and "refused a move" in outcome.reason and stops == [1]
    assert robot.commands == []                                    # nothing above the cap was executed
    assert read_log(tmp_path / "run").stops[-1]["exit_status"] == "fail"


@pytest.mark.unit
def test_mock_refuses_invalid_limits_and_reports_identity(tmp_path):
    world = mock_world(_cell(tmp_path))
    robot = MockRobot(world)
    with pytest.raises(MotionError):
        robot.set_motion_limits(MotionLimits(250.0, 150.0))
    assert robot.identity()["serial"] and MockTracker(world).identity()["firmware"]


@pytest.mark.unit
def test_a_cap_above_the_datasheet_maximum_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"robot\.max_tcp_speed_mm_s.*datasheet maximum"):
        _cell(tmp_path, **{"robot.max_tcp_speed_mm_s": 7500})
    with pytest.raises(ConfigError, match=r"robot\.max_joint_speed_pct"):
        _cell(tmp_path, **{"robot.max_joint_speed_pct": 120})
    assert _cell(tmp_path, **{"robot.max_tcp_speed_mm_s": 7000}).config.robot.max_tcp_speed_mm_s == 7000


@pytest.mark.system
def test_first_pass_traverses_the_plan_at_reduced_caps_before_measuring(tmp_path):
    cell = _cell(tmp_path, **{"robot.first_pass_speed_pct": 25})
    cfg = cell.config
    world = mock_world(cell)
    robot, tracker = MockRobot(world), MockTracker(world)
    plan = build_plan(cell)
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x", "plan_sha256": plan.sha256})
    runner = Runner(robot, tracker, cfg.tracker.measurement, world.clock, lambda p: np.eye(3) * 1e-4,
                    limits=motion_limits(cfg), first_pass_limits=motion_limits(cfg, 25))
    assert runner.execute(plan.points, log).exit_status == "success"
    n = len(plan.points)
    first, measured = robot.commands[:n], robot.commands[n:]
    assert len(measured) == n and max(c.peak_tcp_mm_s for c in first) <= 250 * 0.25 * (1 + 1e-9)
    assert max(c.peak_tcp_mm_s for c in measured) > 250 * 0.25 * 1.5
    events = [e for e in read_log(tmp_path / "run").events if e["type"] == "first_pass"]
    assert [e["state"] for e in events] == ["start", "done"]


# --------------------------------------------------------------------------- swept path


@pytest.mark.unit
def test_a_segment_with_safe_ends_through_a_box_is_blocked(tmp_path):
    kin = _cell(tmp_path).kinematics
    q_a, q_b = np.radians([[-40, 10, 10, 0, 45, 0]]), np.radians([[40, 10, 10, 0, 45, 0]])
    pts = np.array([[0.0, 0.0, 0.0]])
    mid = flange_points_base(kin, (q_a + q_b) / 2, pts)[0, 0]
    box = Boxes(mid[None] - 50, mid[None] + 50)
    ends = flange_points_base(kin, np.vstack([q_a, q_b]), pts)[:, 0]
    assert np.all(np.abs(ends - mid).max(axis=1) > 200)             # both stops far outside the box
    v = check_segments(kin, q_a, q_b, pts, box, None, 0.0)
    assert v.blocked[0] and v.box[0] == 0 and 0.3 < v.s[0] < 0.7
    assert not check_segments(kin, q_a, q_a + 1e-3, pts, box, None, 0.0).blocked[0]


def _random_plan(rng, kin, p_pts):
    """6 random poses near a working configuration, 1-3 boxes placed across their swept paths, and an envelope
    30-200 mm beyond the poses (joint-interpolated arcs bulge out of it)."""
    q_ref = np.array([0, 10, 0, 0, 45, 0.0])
    q = q_ref + rng.uniform(-1, 1, (6, 6)) * np.array([60, 30, 30, 60, 40, 90])
    fl = flange_points_base(kin, np.radians(q), p_pts)[:, 0]
    boxes = []
    for _ in range(rng.integers(1, 4)):
        k = rng.integers(0, 5)
        centre = (fl[k] + fl[k + 1]) / 2 + rng.normal(0, 60, 3)
        half = rng.uniform(40, 150, 3)
        boxes.append((centre - half, centre + half))
    lo, hi = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
    all_pts = flange_points_base(kin, np.radians(np.vstack([q, q_ref])), p_pts).reshape(-1, 3)
    envelope = Boxes(all_pts.min(axis=0)[None] - rng.uniform(30, 200, 3),
                     all_pts.max(axis=0)[None] + rng.uniform(30, 200, 3))
    return q, Boxes(lo, hi), q_ref, envelope


@pytest.mark.system
def test_property_no_planned_swept_path_enters_keep_out_or_leaves_the_envelope(tmp_path):
    """200 random plans: plan_route either routes every move (via poses, a point visited later) or refuses naming
    the pair; on every routed plan a
    4x finer independent sampling of the whole joint path finds no point of the flange or SMR within the
    clearance of a keep-out box or outside the envelope."""
    cell = _cell(tmp_path)
    kin = cell.kinematics
    rng = np.random.default_rng(2026)
    p_pts = np.array([[0.0, 0.0, 0.0], cell.config.tool.p_flange_smr_mm])
    clearance = 20.0
    routed = refused = with_vias = blocked_direct = reordered = by_envelope = 0
    violations = 0
    for trial in range(200):
        q, boxes, q_ref, envelope = _random_plan(rng, kin, p_pts)
        guard = PathGuard(kin, p_pts, boxes, tuple(f"b{i}" for i in range(len(boxes.lo))), envelope, "cell",
                          clearance, q_ref)
        safe = np.array([r is None for r in guard.pose_reasons(q)])
        q = q[safe]
        if len(q) < 2:
            continue
        direct = guard.blocked(q[:-1], q[1:])
        blocked_direct += int(direct.blocked.any())
        by_envelope += int((direct.box == -1).any())
        try:
            order, vias = plan_route(guard, q, [f"Q{i}" for i in range(len(q))])
        except UnsafeMotion as exc:
            refused += 1
            assert "no safe path from point Q" in str(exc) and " to point Q" in str(exc)
            continue
        assert sorted(order) == list(range(len(q)))            # every point visited once
        routed += 1
        with_vias += any(vias)
        reordered += order != sorted(order)
        path = np.array([w for i, v in zip(order, vias) for w in (*v, q[i])])
        fine, _ = sample_segments(np.radians(path[:-1]), np.radians(path[1:]), np.full(len(path) - 1, 400))
        pts = flange_points_base(kin, fine, p_pts).reshape(-1, 3)
        g = boxes.grown(clearance)
        in_box = np.any(np.all((pts[:, None] > g.lo) & (pts[:, None] < g.hi), axis=-1), axis=1)
        e = envelope.grown(-clearance)
        out_env = ~np.all((pts > e.lo[0]) & (pts < e.hi[0]), axis=1)
        violations += int(in_box.sum() + out_env.sum())
    print(f"200 random plans: {routed} routed ({with_vias} with via poses, {reordered} reordered), {refused} refused, "
          f"{blocked_direct} had a blocked direct move ({by_envelope} by the envelope); swept-path violations "
          f"{violations}")
    assert violations == 0
    assert by_envelope >= 20                                        # the envelope is exercised too
    assert with_vias >= 20 and routed >= 100                        # the property is exercised, not vacuous


@pytest.mark.system
def test_plan_refuses_with_the_pair_of_points_when_no_via_clears(tmp_path, capsys):
    from campaign.cli import main
    wall = {"name": "wall", "min_mm": [1050, -4000, -2000], "max_mm": [1150, 4000, 4000]}   # splits the grid in x
    cfg = small_config(tmp_path, **{"plan.grid.step_mm": 400, "plan.test.count": 0,
                                    "plan.check_poses": {"count": 0, "every_n_points": 50}, "plan.keep_out": [wall]})
    assert main(["plan", str(cfg)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "plan.keep_out" in err and "no safe path from point G" in err and "to point G" in err
    assert "keep-out box 'wall'" in err


@pytest.mark.unit
def test_a_move_no_via_clears_is_avoided_by_visiting_a_later_point_first():
    """A table-driven guard: 0 -> 1 cannot be made safe, 0 -> 2 -> 1 -> 3 can; 1 -> 3 needs a via."""
    from types import SimpleNamespace

    impossible = {(0, 1)}
    needs_via = {(1, 3): [(9.0,)]}

    class TableGuard:
        def blocked(self, q_a, q_b):
            pairs = zip(q_a[:, 0].astype(int), q_b[:, 0].astype(int))
            return SimpleNamespace(blocked=np.array([p in impossible or p in needs_via for p in pairs]))

        def route(self, a, b, others=None):
            pair = (int(a[0]), int(b[0]))
            if pair in impossible:
                raise UnsafeMotion("the joint move would pass keep-out box 'x'")
            return needs_via.get(pair, [])
    q = np.arange(4, dtype=float)[:, None]
    order, vias = plan_route(TableGuard(), q, ["A", "B", "C", "D"])
    assert order == [0, 2, 1, 3] and vias == [(), (), (), ((9.0,),)]
    with pytest.raises(UnsafeMotion, match="no safe path from point A to point B"):
        plan_route(TableGuard(), q, ["A", "B", "C", "D"], reorder=0)


@pytest.mark.unit
@pytest.mark.parametrize("key, value, where", [
    ("plan.keep_out", [{"name": "b", "min_mm": [0, 0, 0], "max_mm": [10, -5, 10]}], r"plan\.keep_out\[0\]\.max_mm.*max_mm\.y"),
    ("plan.keep_out", [{"min_mm": [0, 0, 0], "max_mm": [1, 1, 1], "size": 3}], r"plan\.keep_out\[0\]\.size.*unknown key"),
    ("plan.envelope", [1, 2], r"plan\.envelope.*expected a mapping"),
    ("plan.clearance_mm", -1, r"plan\.clearance_mm"),
    ("robot.first_pass_speed_pct", 150, r"robot\.first_pass_speed_pct"),
    ("tracker.measurement.reading_time_s", 0, r"tracker\.measurement\.reading_time_s"),
    ("tool.payload_cog_flange_mm", [0, 0], r"tool\.payload_cog_flange_mm"),
])
def test_safety_keys_are_validated_with_the_key_path(tmp_path, key, value, where):
    with pytest.raises(ConfigError, match=where):
        _cell(tmp_path, **{key: value})
