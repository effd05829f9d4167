"""``campaign select``: N calibration rows of a measured campaign (space-filling, the geometry determined)."""
from __future__ import annotations

import re

import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import read_csv, write_csv
from robocal.design.optimal import criterion, d_optimal
from robocal.identify.identification import register
from tests.campaign.helpers import ROOT
from tests.campaign.hostile import assert_one_line, cli, snapshot
from tests.cells import irb2600, irb2600_poses, make_cell, measure

pytestmark = pytest.mark.system          # `campaign select` through the CLI on simulated campaigns
CONFIG = ROOT / "configs" / "irb2600.yaml"


def _campaign_csv(path):
    kin = irb2600()
    qc, qt = irb2600_poses()
    rng = np.random.default_rng(11)
    cell = make_cell(kin, rng)
    q = np.vstack([qc, qt[:30]])
    p, _ = measure(cell, q, rng)
    ids = [f"G{i:03d}" for i in range(len(qc))] + [f"T{i:03d}" for i in range(30)]
    sets = ["calib"] * len(qc) + ["test"] * 30
    order = np.random.default_rng(0).permutation(len(q))          # test rows among the calib rows
    write_csv(path, Dataset(tuple(np.array(ids)[order]), tuple(np.array(sets)[order]), np.degrees(q[order]),
                            p[order], source=str(path)))
    return path


def _fill_distance(full, sub, cell):
    """Largest distance (mm, joint space scaled by each joint's lever over all rows) from a calibration row of
    ``full`` to its nearest calibration row of ``sub``: how well the subset covers the measured poses."""
    cal = full.mask("calib")
    q, p = np.radians(full.q_deg[cal]), full.p_tracker_mm[cal]
    lever = criterion(register(cell.kinematics, q, p), q, cell.weights(full)[0][cal]).levers_mm_per_rad
    X, Y = q * lever, np.radians(sub.q_deg[sub.mask("calib")]) * lever
    return float(np.max(np.min(np.linalg.norm(X[:, None] - Y[None], axis=2), axis=1)))


def test_select_keeps_n_calibration_rows_every_other_row_and_the_order(tmp_path, capsys):
    data, out = _campaign_csv(tmp_path / "data.csv"), tmp_path / "subset.csv"
    code, text, err = cli(capsys, "select", data, "--config", CONFIG, "--points", 80, "--out", out)
    assert code == 0, err
    assert "selected 80 of" in text and "space-filling" in text
    sub_mm, all_mm = map(float, re.search(r"80 rows ([0-9.]+) mm, all \d+ rows ([0-9.]+) mm", " ".join(text.split())
                                          ).groups())
    assert 0 < all_mm < sub_mm                  # fewer rows: a larger parameter uncertainty at the test rows
    full, sub = read_csv(data), read_csv(out)
    assert int(sub.mask("calib").sum()) == 80 and int(sub.mask("test").sum()) == 30
    pos = [full.point_id.index(i) for i in sub.point_id]
    assert pos == sorted(pos)                                        # measurement order kept
    rows = np.array(pos)
    np.testing.assert_array_equal(sub.q_deg, full.q_deg[rows])
    np.testing.assert_array_equal(sub.p_tracker_mm, full.p_tracker_mm[rows])
    cell = load_cell(CONFIG)
    cal = np.flatnonzero(full.mask("calib"))
    rand = []
    for seed in range(5):
        keep = ~full.mask("calib")
        keep[np.random.default_rng(seed).choice(cal, 80, replace=False)] = True
        rand.append(_fill_distance(full, full.subset(keep), cell))
    q = np.radians(full.q_deg[cal])
    c = criterion(register(cell.kinematics, q, full.p_tracker_mm[cal]), q, cell.weights(full)[0][cal])
    keep = ~full.mask("calib")
    keep[cal[d_optimal(c.A, 80, c.spread).chosen]] = True          # the plan's criterion, for comparison
    assert _fill_distance(full, sub, cell) < min(rand + [_fill_distance(full, full.subset(keep), cell)])


def test_select_refuses_more_rows_than_measured_and_overwriting_its_source(tmp_path, capsys):
    data = _campaign_csv(tmp_path / "data.csv")
    n_cal = int(read_csv(data).mask("calib").sum())
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "select", data, "--config", CONFIG, "--points", n_cal + 1, "--out", tmp_path / "s.csv")
    assert_one_line(code, out, err, 2, f"has {n_cal} calibration rows", f"{n_cal + 1} requested")
    code, out, err = cli(capsys, "select", data, "--config", CONFIG, "--points", 10, "--out", tmp_path / "s.csv")
    assert_one_line(code, out, err, 2, "--points 10", "identifiable + 10 %")
    code, out, err = cli(capsys, "select", data, "--config", CONFIG, "--points", 80, "--out", data)
    assert_one_line(code, out, err, 2, "overwrite")
    five = tmp_path / "five_joints.csv"                        # the data of another robot: q6 missing
    rows = [line.split(",") for line in data.read_text().splitlines()]
    five.write_text("\n".join(",".join(r[:7] + r[8:]) for r in rows) + "\n")
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "select", five, "--config", CONFIG, "--points", 80, "--out", tmp_path / "s.csv")
    assert_one_line(code, out, err, 2, "has 5 joint columns", "6 joints")
    assert snapshot(tmp_path) == before
    far = tmp_path / "far.csv"                                  # a reading no tracker gives
    rows[1][-3] = "1e12"
    far.write_text("\n".join(",".join(r) for r in rows) + "\n")
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "select", far, "--config", CONFIG, "--points", 80, "--out", tmp_path / "s.csv")
    assert_one_line(code, out, err, 2, "not a tracker reading")
    assert snapshot(tmp_path) == before


def test_select_runs_the_plausibility_checks_of_reprocess_and_force_overrides_them(tmp_path, capsys):
    """Another robot's data (an IRB 2600 campaign against the UR10 config): refused as ``reprocess`` refuses it,
    one line, nothing written; ``--force`` selects anyway."""
    data = _campaign_csv(tmp_path / "data.csv")
    other = ROOT / "configs" / "ur10.yaml"
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "select", data, "--config", other, "--points", 80, "--out", tmp_path / "s.csv")
    assert_one_line(code, out, err, 2, "does this data belong to this robot", "--force")
    assert snapshot(tmp_path) == before
    code, out, err = cli(capsys, "select", data, "--config", other, "--points", 80, "--out", tmp_path / "s.csv",
                         "--force")
    assert code == 0, err
    assert int(read_csv(tmp_path / "s.csv").mask("calib").sum()) == 80


def test_select_reads_a_run_directory_like_its_interchange_csv(tmp_path, capsys):
    """``select RUN_DIR`` reads the run's durable log (as ``reprocess`` does) and chooses the same rows as from the
    run's own data.csv; the nest and test rows stay in the subset, which reprocesses."""
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(CONFIG.read_text().replace("dir: runs", f"dir: {tmp_path / 'runs'}"))
    run = tmp_path / "run"
    code, _, err = cli(capsys, "run", cfg, "--out", run)
    assert code == 0, err
    full = read_csv(run / "data.csv")
    n = int(full.mask("calib").sum()) // 3
    code, text, err = cli(capsys, "select", run, "--config", cfg, "--points", n, "--out", tmp_path / "from_log.csv")
    assert code == 0, err
    code, _, err = cli(capsys, "select", run / "data.csv", "--config", cfg, "--points", n,
                       "--out", tmp_path / "from_csv.csv")
    assert code == 0, err
    a, b = read_csv(tmp_path / "from_log.csv"), read_csv(tmp_path / "from_csv.csv")
    assert a.point_id == b.point_id and int(a.mask("calib").sum()) == n
    assert set(a.set) - {"calib"} == set(full.set) - {"calib"}           # test, check and nest rows kept
    assert sum(s != "calib" for s in a.set) == sum(s != "calib" for s in full.set)
    code, _, err = cli(capsys, "reprocess", tmp_path / "from_log.csv", "--config", cfg, "--out", tmp_path / "re")
    assert code == 0, err


def test_select_needs_the_geometry_only_and_notes_when_effects_need_more_rows(tmp_path, capsys):
    """The minimum of ``--points`` is the calibration's own (identifiable geometric parameters + 10 %): one row
    fewer is refused, that many are selected and reprocess; below what also determines every pose-dependent effect
    ``auto`` may take, the output says so; at or above it, it does not."""
    data = _campaign_csv(tmp_path / "data.csv")
    ds, cell = read_csv(data), load_cell(CONFIG)
    cal = ds.mask("calib")
    q = np.radians(ds.q_deg[cal])
    c = criterion(register(cell.kinematics, q, ds.p_tracker_mm[cal]), q, cell.weights(ds)[0][cal], cell.payload_kg)
    geo, every = int(np.ceil(1.1 * c.identifiable_geometric)), int(np.ceil(1.1 * c.identifiable))
    assert geo < every <= int(cal.sum())
    code, out, err = cli(capsys, "select", data, "--config", CONFIG, "--points", geo - 1, "--out", tmp_path / "a.csv")
    assert_one_line(code, out, err, 2, f"--points {geo - 1}", f"{c.identifiable_geometric} geometric",
                    f"at least {geo}")
    code, text, err = cli(capsys, "select", data, "--config", CONFIG, "--points", geo, "--out", tmp_path / "s.csv")
    assert code == 0, err
    assert f"(that needs {every})" in " ".join(text.split())
    code, _, err = cli(capsys, "reprocess", tmp_path / "s.csv", "--config", CONFIG, "--out", tmp_path / "re")
    assert code == 0, err
    code, text, err = cli(capsys, "select", data, "--config", CONFIG, "--points", every, "--out", tmp_path / "e.csv")
    assert code == 0, err
    assert "note:" not in text


def test_a_subset_keeps_how_the_robot_reached_each_pose(tmp_path, capsys):
    """A read-back lag (the truth simulator: read-back offset proportional to the signed last move) and backlash
    depend on the move that reached a pose. ``select`` writes each chosen row's approach and last moves from the full
    measurement order; ``reprocess`` of the subset then models them as all rows do (measured, held-out RMS: lag
    0.037 against 0.036 mm, backlash 0.0345 against 0.0326 mm). Computed from the subset's own neighbours instead,
    the lag subset gave 0.89 mm."""
    from campaign.calibrate.stages import calibrate_dataset
    from robocal.simulation.truth_cell import simulate
    from tests.campaign.helpers import truth_csv

    figures = []
    for k, effect in enumerate(("readback_lag", "backlash")):
        d = tmp_path / effect
        d.mkdir()
        data, cfg = truth_csv(d, simulate((effect,), 1005 - k))
        code, _, err = cli(capsys, "select", data, "--config", cfg, "--points", 100, "--out", d / "sub.csv")
        assert code == 0, err
        assert (d / "sub.csv").read_text().splitlines()[1].endswith(",order")     # after its provenance line
        cell = load_cell(cfg)
        everything = calibrate_dataset(read_csv(data), cell).report.final.test.rms_mm
        chosen = calibrate_dataset(read_csv(d / "sub.csv"), cell).report.final.test.rms_mm
        figures.append(f"{effect}: held-out RMS all rows {everything:.4f} mm, 100 selected {chosen:.4f} mm")
        assert chosen < 1.2 * everything, figures[-1]
    with capsys.disabled():
        print("\n" + "\n".join(figures))
