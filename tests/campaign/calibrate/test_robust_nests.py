"""Misread reference nests: set aside and listed before the drift model is fitted (``preparation.drift.excluded``),
re-read once during a run, and a nest read only once is bad input."""
from dataclasses import replace

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.cell_model import CellModel
from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import write_csv
from campaign.calibrate.prepare import prepare
from campaign.calibrate.stages import calibrate_dataset
from campaign.run.log_reader import read_log
from robocal.simulation.truth_cell import TruthProtocol, simulate, warmup
from tests.campaign.helpers import ROOT, read_report, small_config
from tests.campaign.test_phenomena import phenomena_config

CELL = load_cell(ROOT / "configs/irb2600.yaml")
CFG = CELL.config


def truth_dataset(camp) -> Dataset:
    """A simulated campaign (robocal.simulation.truth_cell) as the interchange dataset: robot rows with the commanded joints, each
    followed by the nest readings taken after it (set ``nest``, no joints)."""
    after: dict[int, list[int]] = {}
    for k, r in enumerate(camp.nest_after_row):
        after.setdefault(int(r), []).append(k)
    q, p, t, sets, ids, nest_ids = [], [], [], [], [], []
    for i in range(len(camp.sets)):
        q.append(np.degrees(camp.q_cmd_rad[i]))
        p.append(camp.p_mm[i])
        t.append(camp.t_s[i])
        sets.append(camp.sets[i])
        ids.append(camp.point_id[i])
        nest_ids.append("")
        for k in after.get(i, []):
            q.append(np.full(camp.q_cmd_rad.shape[1], np.nan))
            p.append(camp.nest_p_mm[k])
            t.append(camp.nest_t_s[k])
            sets.append("nest")
            ids.append(f"{camp.nest_id[k]}@{k:04d}")
            nest_ids.append(camp.nest_id[k])
    return Dataset(tuple(ids), tuple(sets), np.array(q), np.array(p), t_s=np.array(t), nest_id=tuple(nest_ids),
                   source="nests-sim")


def true_drift_mm(camp, ds: Dataset) -> np.ndarray:
    """The simulated stand drift (N, 3) mm at the robot rows of ``ds`` (robocal.simulation.truth_cell's registration_drift)."""
    v = camp.truths[0].values
    robot = ~ds.mask("nest")
    t = ds.t_s[robot]
    s = t / 3600.0 if v["linear"] else warmup(t, v["tau_s"])
    origin = camp.truth_kin.T_tracker_base[:3, 3]
    return s[:, None] * (v["v_mm"] + np.cross(v["w_rad"], ds.p_tracker_mm[robot] - origin))


def with_misreads(ds: Dataset, fraction: float, rng) -> tuple[Dataset, np.ndarray]:
    """``fraction`` of the nest readings off by 400, 10 and 2 mm (in turn) in random directions."""
    rows = np.flatnonzero(ds.mask("nest"))
    bad = rng.choice(rows, max(3, int(round(fraction * len(rows)))), replace=False)
    d = rng.normal(size=(len(bad), 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = ds.p_tracker_mm.copy()
    p[bad] += d * np.resize([400.0, 10.0, 2.0], len(bad))[:, None]
    return replace(ds, p_tracker_mm=p), bad


@pytest.mark.system
def test_misread_nests_are_set_aside_and_the_drift_and_result_stay():
    """Three floor nests read after every pose (~880 readings), 0.5 % of them misread by 400, 10 or 2 mm: every
    misread is excluded and listed, no clean reading is, the drift is recovered within 10 um RMS and the held-out
    RMS equals the run without misreads within 2 % (the truth has no effect but the drift: the geometric model is
    the whole pipeline here, effect selection and residual layer are switched off to keep the test short)."""
    pr = TruthProtocol(n_calib=200, n_test=80, check_poses=4, check_repeats=3, nest_every=1, payloads_kg=(0.0,))
    calibration = replace(CFG.calibration, effects="none", residual="none")
    for seed in (0, 1):
        camp = simulate(["registration_drift"], seed, pr)
        cell = CellModel.from_config(replace(CFG, calibration=calibration, tool=replace(
            CFG.tool, p_flange_smr_mm=tuple(map(float, camp.nominal.p_flange_smr_mm)))))
        clean = truth_dataset(camp)
        bad_ds, bad = with_misreads(clean, 0.005, np.random.default_rng(seed))
        true = true_drift_mm(camp, clean)
        robot = ~clean.mask("nest")
        rms = {}
        for name, ds in (("clean", clean), ("misread", bad_ds)):
            prep = prepare(ds, cell)
            drift = prep.report["drift"]
            excluded = {e["point_id"] for e in drift["excluded"]}
            assert excluded == ({clean.point_id[i] for i in bad} if name == "misread" else set())
            assert all("misread" in e["reason"] for e in drift["excluded"])
            err = (ds.p_tracker_mm[robot] - prep.dataset.p_tracker_mm) - true
            err_um = 1000 * np.sqrt(np.mean(np.sum(err**2, axis=1)))
            rms[name] = calibrate_dataset(ds, cell).report.final.test.rms_mm
            print(f"seed {seed} {name}: {len(excluded)} nest readings excluded of {len(bad)} misread, drift "
                  f"{drift['model']['degree']}{'+rotation' if drift['model']['rotation'] else ''} (CV RMS "
                  f"{drift['cv_rms_mm']:.4f} mm), drift error {err_um:.1f} um RMS (drift itself "
                  f"{1000 * np.sqrt(np.mean(np.sum(true**2, axis=1))):.0f} um RMS), max nest move "
                  f"{drift['max_nest_move_mm']:.3f} mm, held-out RMS {rms[name]:.4f} mm")
            assert drift["applied"] and err_um < 10.0 and drift["max_nest_move_mm"] < 1.0
        assert abs(rms["misread"] / rms["clean"] - 1.0) < 0.02


@pytest.mark.unit
def test_a_nest_read_once_is_bad_input(tmp_path, capsys):
    from campaign.config.simulation import simulated_cell
    rng = np.random.default_rng(3)
    n = 14
    q = np.vstack([rng.uniform(-40, 40, (n, 6)), np.full((3, 6), np.nan)])
    p_robot, _ = simulated_cell(CELL).measure(np.radians(q[:n]), rng)
    p = np.vstack([p_robot, [[1000, 0, 0], [1000, 0, 0.01], [0, 900, 0]]])
    ds = Dataset(tuple(f"P{i}" for i in range(n)) + ("N1@001", "N1@002", "N2@001"), ("calib",) * n + ("nest",) * 3,
                 q, p, t_s=np.arange(n + 3) * 5.0, nest_id=("",) * n + ("N1", "N1", "N2"))
    write_csv(tmp_path / "d.csv", ds)
    cfg = small_config(tmp_path)
    assert main(["reprocess", str(tmp_path / "d.csv"), "--config", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nest_id 'N2' has a single reading" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.system
def test_a_misread_nest_is_read_again_before_the_run_pauses(tmp_path, monkeypatch):
    """The tracker misreads one nest reading by 400 mm: the runner reads the nest once more, keeps the misread in a
    ``nest_reread`` event and goes on; the log's nest record is the second reading."""
    from drivers.mock import MockTracker
    calls = []
    real = MockTracker.select_nest

    def misread_once(self, nest_id, guess=None):
        real(self, nest_id, guess)
        calls.append(nest_id)
        if len(calls) == 5:
            self.nest_error_mm = self.nest_error_mm + np.array([400.0, 0.0, 0.0])
    monkeypatch.setattr(MockTracker, "select_nest", misread_once)
    cfg = phenomena_config(tmp_path, **{"simulation.tracker_drift_mm_per_h": [0.0, 0.0, 0.0],
                                        "simulation.tracker_drift_urad_per_h": [0.0, 0.0, 0.0]})
    assert main(["run", str(cfg), "--out", str(tmp_path / "run")]) == 0
    log = read_log(tmp_path / "run")
    rereads = [e for e in log.events if e.get("type") == "nest_reread"]
    assert len(rereads) == 1 and rereads[0]["first_reading"]["point_id"] == "N2@002"
    first = np.array(rereads[0]["first_reading"]["p_tracker_mm"])
    kept = next(np.array(r["p_tracker_mm"]) for r in log.points if r["point_id"] == "N2@002")
    assert 399 < np.linalg.norm(first - kept) < 401
    assert read_report(tmp_path / "run").preparation["drift"]["excluded"] == []
