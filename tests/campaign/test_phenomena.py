"""Real-cell phenomena end to end on the mock cell: commanded vs read-back joints, reference nests and tracker
drift, environment columns, and bad input in the interchange CSV (exit 2, one line, nothing written)."""

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.data.log_dataset import dataset_from_log
from campaign.calibrate.prepare import prepare
from campaign.run.log_reader import LogContents, read_log
from tests.campaign.helpers import read_report, small_config

NESTS = [{"id": "N1", "p_base_mm": [1500, -1200, 0]}, {"id": "N2", "p_base_mm": [1600, 1300, 50]},
         {"id": "N3", "p_base_mm": [-700, 100, 0]}]
V_MM_H, W_URAD_H = [1.6, -1.0, 0.8], [120.0, -80.0, 160.0]   # fast: the small plan takes minutes


def phenomena_config(tmp_path, **more):
    return small_config(
        tmp_path, **{"plan.order": "random", "plan.order_seed": 2,
                     "plan.nests": {"every_n_points": 15, "max_move_mm": 0.5, "points": NESTS},
                     "simulation.readback_lag_deg_per_deg": [-0.0005, -0.0005, -0.0005, -0.0002, -0.0002, -0.0002],
                     "simulation.readback_noise_deg": 0.002,
                     "simulation.tracker_drift_mm_per_h": V_MM_H, "simulation.tracker_drift_urad_per_h": W_URAD_H,
                     **more})


@pytest.fixture(scope="module")
def lag_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("phen")
    cfg = phenomena_config(tmp)
    assert main(["run", str(cfg), "--out", str(tmp / "run")]) == 0
    return cfg, tmp / "run"


@pytest.mark.system
def test_run_exports_both_joint_sets_and_nest_rows(lag_run):
    _, run = lag_run
    ds = read_csv(run / "data.csv")
    robot = ~ds.mask("nest")
    assert ds.qc_deg is not None and ds.mask("nest").sum() >= 3 * 3
    assert np.all(np.isnan(ds.q_deg[~robot])) and np.all(np.isfinite(ds.q_deg[robot]))
    d = ds.q_deg[robot] - ds.qc_deg[robot]
    assert 0.005 < np.sqrt(np.mean(d**2)) < 0.2                      # read-back lags the command
    assert set(np.array(ds.nest_id)[~robot]) == {"N1", "N2", "N3"}
    log = read_log(run)
    nests = [r for r in log.points if r["set"] == "nest"]
    assert all(r["kind"] == "nest" and "t_s" in r and r["nest_id"] for r in nests)
    assert [r["point_id"] for r in nests][:3] == ["N1@001", "N2@001", "N3@001"]


@pytest.mark.system
def test_auto_picks_commanded_joints_and_compensates_the_nest_drift(lag_run):
    cfg_path, run = lag_run
    ds = read_csv(run / "data.csv")
    prep = prepare(ds, load_cell(cfg_path))
    assert prep.joints == "commanded" and "last move" in prep.report["joints"]["why"]
    robot = ~ds.mask("nest")
    np.testing.assert_array_equal(prep.dataset.q_deg, ds.qc_deg[robot])
    assert prep.dataset.qc_deg is None and not prep.dataset.mask("nest").any()
    assert prep.drift is not None and prep.drift.degree >= 1 and prep.report["drift"]["applied"]
    # the correction applied to the robot rows against the simulator's drift (up to a constant: registration)
    p_raw, t = ds.p_tracker_mm[robot], ds.t_s[robot]
    applied = p_raw - prep.dataset.p_tracker_mm
    true = (t / 3600.0)[:, None] * (np.array(V_MM_H) + np.cross(np.array(W_URAD_H) * 1e-6, p_raw))
    applied, true = applied - applied.mean(axis=0), true - true.mean(axis=0)
    rms = lambda a: float(np.sqrt(np.mean(np.sum(a**2, axis=1))))  # noqa: E731
    print(f"drift over the robot rows {rms(true):.4f} mm RMS; model error {rms(applied - true):.4f} mm RMS")
    assert rms(true) > 0.03
    assert rms(applied - true) < 0.35 * rms(true)
    # forcing read-back joints is obeyed and said
    (run.parent / "f").mkdir(exist_ok=True)
    forced = prepare(ds, load_cell(phenomena_config(run.parent / "f", **{"calibration.joints": "readback"})))
    assert forced.joints == "readback" and "calibration.joints: readback" in forced.report["joints"]["why"]
    np.testing.assert_array_equal(forced.dataset.q_deg, ds.q_deg[robot])


@pytest.mark.system
def test_auto_keeps_readback_joints_when_the_robot_stood_there(lag_run):
    """Swap the sets: the robot really stood at the read-back joints and the commands lagged. The statistics
    alone would take the commanded set; the geometric fit of each set must overrule them."""
    from dataclasses import replace
    cfg_path, run = lag_run
    ds = read_csv(run / "data.csv")
    swapped = replace(ds, q_deg=ds.qc_deg, qc_deg=ds.q_deg)
    prep = prepare(swapped, load_cell(cfg_path))
    rep = prep.report["joints"]
    assert prep.joints == "readback" and "follow the read-back joints" in rep["why"]
    assert rep["geometric_fit_rms_readback_mm"] < 0.9 * rep["geometric_fit_rms_commanded_mm"]


@pytest.mark.system
def test_reprocess_reports_the_choice(lag_run, tmp_path):
    cfg, run = lag_run
    assert main(["reprocess", str(run / "data.csv"), "--config", str(cfg), "--out", str(tmp_path / "rp")]) == 0
    rep = read_report(tmp_path / "rp").preparation
    assert rep["joints"]["used"] == "commanded" and rep["drift"]["nests"] == 3


@pytest.mark.system
def test_nest_that_moves_beyond_the_bound_pauses_the_run(tmp_path, capsys):
    cfg = phenomena_config(tmp_path, **{"simulation.tracker_drift_mm_per_h": [40.0, 0.0, 0.0],
                                        "plan.nests": {"every_n_points": 15, "max_move_mm": 0.5, "points": NESTS}})
    assert main(["run", str(cfg), "--out", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err
    assert "moved" in err and "plan.nests.max_move_mm" in err and "--resume" in err
    log = read_log(tmp_path / "run")
    assert log.stops[-1]["exit_status"] == "paused" and log.points[-1]["set"] == "nest"   # the reading is kept


@pytest.mark.unit
def test_nest_qc_env_columns_round_trip(tmp_path):
    n = 6
    rng = np.random.default_rng(0)
    sets = ("nest", "calib", "calib", "test", "check", "nest")
    q = rng.uniform(-90, 90, (n, 6))
    q[[0, 5]] = np.nan
    env = np.array([20.0, 20.1, np.nan, 20.3, 20.4, 20.5])
    ds = Dataset(("N1@001", "P1", "P2", "T1", "K1", "N1@002"), sets, q, rng.normal(size=(n, 3)) * 1000,
                 t_s=np.arange(n) * 3.0, qc_deg=q + 0.01, nest_id=("N1", "", "", "", "", "N1"), env_temp_c=env,
                 env_pressure_hpa=np.full(n, 1013.2))
    write_csv(tmp_path / "d.csv", ds)
    back = read_csv(tmp_path / "d.csv")
    np.testing.assert_array_equal(back.q_deg, ds.q_deg)
    np.testing.assert_array_equal(back.qc_deg, ds.qc_deg)
    np.testing.assert_array_equal(back.env_temp_c, env)
    assert back.nest_id == ds.nest_id and back.env_humidity_pct is None
    np.testing.assert_array_equal(back.approach_sign()[[0, 5]], 0.0)


@pytest.mark.unit
def test_log_environment_and_nest_records_become_columns():
    def point(i, **kw):
        return {"point_id": f"P{i}", "set": "calib", "q_cmd_deg": [i, 2.0], "q_read_deg": [i + 0.01, 2.0],
                "p_tracker_mm": [i, 0.0, 0.0], "t_end_s": 100.0 + i, **kw}
    recs = [{"point_id": "N1@001", "set": "nest", "kind": "nest", "nest_id": "N1", "p_tracker_mm": [5.0, 5.0, 5.0],
             "t_end_s": 99.0, "temperatures": {"temp_c": 19.5, "pressure_hpa": 1001.0, "humidity_pct": 40.0}},
            point(1, temperatures={"temp_c": 20.0, "pressure_hpa": 1000.0, "humidity_pct": 41.0}),
            point(2, temperatures={"temp_c": 20.2})]
    ds = dataset_from_log(LogContents(start={}, points=recs, path="log.jsonl"))
    assert ds.set == ("nest", "calib", "calib") and ds.nest_id == ("N1", "", "")
    np.testing.assert_array_equal(ds.env_pressure_hpa, [1001.0, 1000.0, np.nan])
    np.testing.assert_array_equal(ds.qc_deg[1:], [[1, 2], [2, 2]])
    np.testing.assert_allclose(ds.q_deg[1:, 0], [1.01, 2.01])
    assert np.isnan(ds.q_deg[0]).all() and ds.t_s.tolist() == [0.0, 2.0, 3.0]


HEADER = "point_id,set,q1,q2,q3,q4,q5,q6,x,y,z"
ROW = "P1,calib,1,2,3,4,5,6,1000,200,300"
BAD = {
    "qc_fewer": (HEADER + ",qc1,qc2,qc3,qc4,qc5\n" + ROW + ",1,2,3,4,5\n", "line 1, column 'qc6'"),
    "qc_more": (HEADER + ",qc1,qc2,qc3,qc4,qc5,qc6,qc7\n" + ROW + ",1,2,3,4,5,6,7\n", "line 1, column 'qc7'"),
    "nest_without_id": (HEADER + ",t_s,nest_id\n" + ROW + ",0,\nN@1,nest,,,,,,,1,2,3,1,\n",
                        "line 3, column 'nest_id': nest row without a nest id"),
    "nest_without_id_column": (HEADER + ",t_s\n" + ROW + ",0\nN@1,nest,,,,,,,1,2,3,1\n",
                               "line 3, column 'nest_id'"),
    "nest_without_time": (HEADER + ",nest_id\n" + ROW + ",\nN@1,nest,,,,,,,1,2,3,N\n", "line 3, column 't_s'"),
    "smr_group_partial": (HEADER + ",x2,y2\n" + ROW + ",1,2\n", "line 1, column 'z2'"),
    "smr_cell_missing": (HEADER + ",x2,y2,z2\n" + ROW + ",1,,3\n", "line 2, column 'y2'"),
    "empty_joint_on_calib": (HEADER + "\nP1,calib,1,,3,4,5,6,1000,200,300\n", "line 2, column 'q2'"),
}


@pytest.mark.system
def test_commanded_joints_in_other_units_are_refused(lag_run, tmp_path, capsys):
    from dataclasses import replace
    cfg, run = lag_run
    ds = read_csv(run / "data.csv")
    write_csv(tmp_path / "rad.csv", replace(ds, qc_deg=np.radians(ds.qc_deg)))
    out = tmp_path / "out"
    assert main(["reprocess", str(tmp_path / "rad.csv"), "--config", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "not the same poses" in err and "rad.csv" in err and "\n" not in err and not out.exists()


@pytest.mark.system
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_phenomena_csv_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, case):
    text, where = BAD[case]
    csv = tmp_path / "data.csv"
    csv.write_text(text)
    out = tmp_path / "out"
    assert main(["reprocess", str(csv), "--config", str(small_config(tmp_path)), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(csv) in err and where in err, err
    assert not out.exists()


@pytest.mark.system
def test_plan_nest_rounds_and_random_order(tmp_path):
    from campaign.plan.build import build_plan

    cell = load_cell(phenomena_config(tmp_path))
    plan = build_plan(cell)
    sets = [p.set for p in plan.points]
    assert sets[:3] == ["nest"] * 3 and sets[-3:] == ["nest"] * 3
    robot_between = [len(list(g)) for k, g in __import__("itertools").groupby(sets, key=lambda s: s == "nest") if not k]
    assert max(robot_between) == 15 and all(n <= 15 for n in robot_between)
    waits = [(a.q_deg, b.q_deg) for a, b in zip(plan.points, plan.points[1:]) if b.set == "nest"]
    assert all(qa == qb for qa, qb in waits)                    # the robot waits where it is
    assert plan.points[0].q_deg == plan.points[3].q_deg
    grid = np.array([p.p_base_mm for p in plan.points if p.set == "calib"])
    step = np.median(np.linalg.norm(np.diff(grid, axis=0), axis=1))
    assert step > 2 * cell.config.plan.grid.step_mm             # serpentine order would step to a neighbour
    again = build_plan(load_cell(phenomena_config(tmp_path)))
    assert again.sha256 == plan.sha256                          # seeded


@pytest.mark.system
def test_paused_nest_run_resumes_without_losing_a_reading(tmp_path, capsys):
    cfg = phenomena_config(tmp_path, **{"simulation.tracker_drift_mm_per_h": [3.0, 0.0, 0.0],
                                        "plan.nests": {"every_n_points": 15, "max_move_mm": 0.1, "points": NESTS}})
    run = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 1
    n_paused = len(read_log(run).points)
    # the drift goes on after the resume: the next nest round pauses again; nothing is lost or repeated
    assert main(["run", str(cfg), "--resume", str(run)]) == 1
    log = read_log(run)
    ids = [p["point_id"] for p in log.points]
    plan_ids = {r.split(",")[0] for r in (run / "plan.csv").read_text().splitlines()[1:]}
    assert len(ids) > n_paused and len(set(ids)) == len(ids) and set(ids) <= plan_ids
    assert [e["type"] for e in log.events].count("pause") == 2 and log.points[-1]["set"] == "nest"


class _AimByPosition:
    """A tracker that can only aim at a position (reacquire), like a line-protocol tracker without nest support."""

    def __init__(self, mock):
        self.mock, self.aimed = mock, []

    def __getattr__(self, name):
        if name in ("select_nest",):
            raise AttributeError(name)
        return getattr(self.mock, name)

    def reacquire(self, guess):
        self.aimed.append(tuple(guess))
        w = self.mock.world
        near = [k for k in w.nests if np.linalg.norm(w.nest_tracker_mm(k) - np.asarray(guess)) < 5.0]
        if not near:
            from drivers.base import TargetNotFound
            raise TargetNotFound(f"nothing within 5 mm of {guess}")
        self.mock.select_nest(near[0])


@pytest.mark.system
def test_nests_with_a_position_only_tracker(tmp_path):
    from drivers.base import DriverError
    from campaign.run.devices import mock_world
    from campaign.plan.build import build_plan
    from campaign.run.log_writer import RunLog
    from campaign.run.runner import Runner
    from drivers.mock import MockRobot, MockTracker

    cell = load_cell(phenomena_config(tmp_path))
    cfg = cell.config
    world = mock_world(cell)
    tracker = _AimByPosition(MockTracker(world))
    args = (MockRobot(world), tracker, cfg.tracker.measurement, world.clock, lambda p: np.eye(3) * 1e-4)
    with pytest.raises(DriverError, match="p_tracker_mm for nest N1"):
        Runner(*args, nests=cfg.plan.nests)
    T = world.cell.truth.T_tracker_base
    guessed = [dict(n, p_tracker_mm=(T[:3, :3] @ n["p_base_mm"] + T[:3, 3] + 1.0).tolist()) for n in NESTS]
    cell = load_cell(phenomena_config(tmp_path, **{"plan.nests": {"every_n_points": 15, "points": guessed}}))
    runner = Runner(*args, nests=cell.config.plan.nests)
    plan = build_plan(cell)
    log = RunLog.create(tmp_path / "run", {"config_sha256": "x"})
    assert runner.execute(plan.points[:40], log).exit_status == "success"
    nests = [r for r in read_log(tmp_path / "run").points if r["set"] == "nest"]
    assert len(nests) >= 6 and len(tracker.aimed) == len(nests)
    np.testing.assert_allclose(tracker.aimed[3], nests[0]["p_tracker_mm"])   # second round: at the last reading


@pytest.mark.unit
def test_a_failed_weather_read_does_not_block_the_export():
    recs = [{"point_id": f"P{i}", "set": "calib", "q_cmd_deg": [i, 0.0], "q_read_deg": [i, 0.0],
             "p_tracker_mm": [i, 0.0, 0.0], "t_end_s": float(i),
             **({} if i == 1 else {"temperatures": {"temp_c": 20.0 + i}})} for i in range(3)]
    ds = dataset_from_log(LogContents(start={}, points=recs, path="log.jsonl"))
    assert ds.temp_c is None
    np.testing.assert_array_equal(ds.env_temp_c, [20.0, np.nan, 22.0])


@pytest.mark.unit
@pytest.mark.parametrize("nests, where", [
    ({"points": [{"p_base_mm": [0, 0, 0]}]}, "plan.nests.points[0]: missing required key 'id'"),
    ({"points": [NESTS[0], dict(NESTS[1], id="N1")]}, "plan.nests.points[1].id: duplicate nest id 'N1'"),
    ({"points": [NESTS[0]], "max_move_mm": 0}, "plan.nests.max_move_mm"),
    ({"points": [{"id": "N1", "p_base_mm": [0, 0]}]}, "plan.nests.points[0].p_base_mm"),
])
def test_bad_nest_config_is_one_line_exit_2(tmp_path, capsys, nests, where):
    cfg = small_config(tmp_path, **{"plan.nests": nests})
    assert main(["validate", str(cfg)]) == 2
    err = capsys.readouterr().err.strip()
    assert where in err and "\n" not in err
