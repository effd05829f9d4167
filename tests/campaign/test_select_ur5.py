"""``campaign select`` on the public UR5 campaign (tests/data/serial_robots_datasets, MIT): 100 of the 1000 grid
poses chosen by ``campaign select``, then the DEFAULT ``reprocess`` (configs/ur5.yaml), judged on the 20 random
held-out poses against all 1000 poses and against 10 seeded random 100-subsets (``-s`` prints them).
Measured: 0.0656 mm against 0.0595 mm with all 1000 (1.10 x; paired bootstrap over the 20 held-out poses
0.98-1.25 x) and a random median of 0.0692 mm. Two changes made the goal reachable, each chosen by held-out
prediction over this campaign and simulated cells, not on this test: the joint-error GP layer
(bench/bench_joint_gp.py: 100-row subsets of this campaign 0.72-0.86 x the error without it) and the
space-filling choice of rows (bench/bench_select.py). Before them: 0.0879 mm against 0.0616 mm (1.43 x)."""
from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

import numpy as np
import pytest

from campaign.config.load import load_cell
from campaign.cli import main
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.calibrate.stages import calibrate_dataset
from tests.campaign.helpers import ROOT, read_report

pytestmark = pytest.mark.system

UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
CONFIG = ROOT / "configs" / "ur5.yaml"
N_POINTS, N_RANDOM = 100, 10
GOAL = 1.2                      # issue 22: 100 chosen poses within 1.2 x the held-out error of all 1000


def _held_out_mean_mm(ds, cell) -> float:
    return float(calibrate_dataset(ds, cell).report.final.test.mean_mm)


def _test_errors_mm(ds, cell) -> dict[str, float]:
    """Final-model 3-D error (mm) per test point id."""
    pts = calibrate_dataset(ds, cell).points
    test = np.array([s == "test" for s in pts.set])
    return dict(zip(np.array(pts.point_id)[test], np.linalg.norm(pts.err_base_mm["compensated"][test], axis=1)))


def _bootstrap_ratio(chosen: dict, everything: dict, seed: int = 0) -> np.ndarray:
    """5 / 50 / 95 % of the mean-error ratio chosen / all over 20 000 paired resamples of the test points."""
    ids = sorted(everything)
    a, c = np.array([everything[i] for i in ids]), np.array([chosen[i] for i in ids])
    b = np.random.default_rng(seed).integers(0, len(ids), (20_000, len(ids)))
    return np.percentile(c[b].mean(1) / a[b].mean(1), [5, 50, 95])


def _cli(*argv) -> tuple[int, str]:
    """``campaign ARGV`` in-process (a module-scoped fixture has no capsys): exit code and stderr."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, err.getvalue()


@dataclass(frozen=True)
class Figures:
    """Held-out mean error (mm) of the 100 rows chosen by ``campaign select``, of all rows, of random subsets."""
    chosen_mm: float
    all_mm: float
    random_mm: tuple[float, ...]


@pytest.fixture(scope="module")
def figures(tmp_path_factory) -> Figures:
    importers = pytest.importorskip("campaign.data.importers", reason="needs the UR5 importer (campaign import)")
    if not (UR5.exists() and CONFIG.exists()):
        pytest.skip("needs the vendored UR5 campaign and configs/ur5.yaml")
    tmp = tmp_path_factory.mktemp("select_ur5")
    data, subset, out = tmp / "data.csv", tmp / "subset.csv", tmp / "out"
    write_csv(data, importers.import_target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                                                UR5 / "3D_UR5_uncalibrated_random_cleaned.csv"))
    code, err = _cli("select", data, "--config", CONFIG, "--points", N_POINTS, "--out", subset)
    assert code == 0, err
    code, err = _cli("reprocess", subset, "--config", CONFIG, "--out", out)
    assert code == 0, err
    report = read_report(out)
    assert report.n.calib == N_POINTS and report.n.test == 20
    cell = load_cell(CONFIG)
    full = read_csv(data)
    cal = np.flatnonzero(full.mask("calib"))
    random = []
    for seed in range(N_RANDOM):
        keep = ~full.mask("calib")
        keep[np.random.default_rng(seed).choice(cal, N_POINTS, replace=False)] = True
        random.append(_held_out_mean_mm(full.with_order_context().subset(keep), cell))   # as select writes a subset
    f = Figures(float(report.final.test.mean_mm), _held_out_mean_mm(full, cell),
                tuple(random))
    lo, mid, hi = _bootstrap_ratio(_test_errors_mm(read_csv(subset), cell), _test_errors_mm(full, cell))
    print(f"\nUR5 public campaign, mean error on the 20 random held-out poses (mm), default reprocess: "
          f"all {len(cal)} grid poses {f.all_mm:.4f}; {N_POINTS} chosen by campaign select {f.chosen_mm:.4f} "
          f"({f.chosen_mm / f.all_mm:.3f} x all); median of {N_RANDOM} random {N_POINTS}-subsets "
          f"{np.median(random):.4f} (each: {', '.join(f'{v:.4f}' for v in random)}); ratio chosen / all over "
          f"paired bootstrap resamples of the 20 held-out poses: 5 % {lo:.2f}, median {mid:.2f}, 95 % {hi:.2f}")
    return f


def test_select_100_of_1000_ur5_poses_beats_random_subsets(figures):
    assert figures.chosen_mm < float(np.median(figures.random_mm))


def test_select_100_of_1000_ur5_poses_reaches_the_goal(figures):
    assert figures.chosen_mm <= GOAL * figures.all_mm
