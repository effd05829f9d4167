"""Calibration time of the DEFAULT `reprocess` (campaign.calibrate.stages.calibrate_dataset: preparation, plausibility, geometry, fault
screen, effects selection, residual-layer choice and the stage table; report.json / model.json / report.html not
written) for 1000 and 3000 simulated points and the public UR5 campaign. Targets: <= 3 s (1000), <= 10 s (3000).

Also the unit of work of the GP hyperparameter search (the hot spot: one likelihood + gradient on 300 points), with
the inverse by LAPACK potri (now) against the solve with the identity it replaced, in the same run.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_reprocess.py [--repeats 3]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import cho_factor, cho_solve  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from campaign.config.load import load_cell  # noqa: E402
from campaign.data.dataset import Dataset  # noqa: E402
from campaign.data.importers import import_target_dif  # noqa: E402
from campaign.calibrate.calibration_report import CalibrationReport  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from robocal.effects.bases import joint_compliance  # noqa: E402
from robocal.kinematics.frames import make_T, rotvec_to_matrix  # noqa: E402
from robocal.layers.gp import cholesky_inverse, nlml_shared, se_ard  # noqa: E402
from robocal.simulation.mock_cell import SimulatedCell, random_geometric_errors  # noqa: E402

UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
TARGETS_S = {1000: 3.0, 3000: 10.0}


def simulated(cell, n_calib: int, n_test: int = 100, seed: int = 1) -> Dataset:
    """A UR5 cell with seeded geometric errors and J2/J3 gravity compliance; poses +-35 deg around the public
    campaign's mean pose (the flange turns); GTS3800 noise + 0.1 mm repeatability."""
    rng = np.random.default_rng(seed)
    truth = random_geometric_errors(cell.kinematics, rng).with_(
        T_tracker_base=make_T(rotvec_to_matrix([0.01, -0.02, 0.5]), [2500.0, 300.0, -200.0]),
        p_flange_smr_mm=[0.3, -0.4, 33.0])
    sim = SimulatedCell(truth, ((joint_compliance((2, 3)), np.array([3e-6, 4e-6])),), cell.tracker, 0.1)
    n = n_calib + n_test
    q = np.radians([19, -64, 102, -41, 99, 0]) + np.radians(rng.uniform(-35, 35, (n, 6)))
    p, _ = sim.measure(q, rng)
    return Dataset(tuple(f"P{i:04d}" for i in range(n)), ("calib",) * n_calib + ("test",) * n_test, np.degrees(q), p,
                   source="simulated")


def timed(ds, cell, repeats: int) -> tuple[float, float, CalibrationReport]:
    """(median wall s, median CPU s, report of the last run)."""
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        report = calibrate_dataset(ds, cell).report
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return float(np.median(wall)), float(np.median(cpu)), report


def likelihood_unit(repeats: int = 200) -> None:
    """One nlml + gradient on 300 points (6 inputs, 3 outputs): potri inverse vs the solve with the identity."""
    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(300, 6)), rng.normal(size=(300, 3))
    theta = np.log(np.r_[1.0, 0.3, np.ones(6)])
    H = se_ard(X, X, np.ones(6), 1.0) + 0.09 * np.eye(300)
    c = cho_factor(H, lower=True)
    np.testing.assert_allclose(cholesky_inverse(c), cho_solve(c, np.eye(300)), rtol=1e-9, atol=1e-12)

    def per_call_ms(f) -> float:
        t = time.process_time()
        for _ in range(repeats):
            f()
        return (time.process_time() - t) / repeats * 1e3
    inv_new, inv_old = per_call_ms(lambda: cholesky_inverse(c)), per_call_ms(lambda: cho_solve(c, np.eye(300)))
    full = per_call_ms(lambda: nlml_shared(theta, X, Y, 1e-10))
    print(f"GP likelihood + gradient, 300 points: {full:.2f} ms per evaluation (CPU); its inverse: potri {inv_new:.2f} ms "
          f"vs solve with the identity {inv_old:.2f} ms (ratio {inv_old / inv_new:.1f})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cell = load_cell(ROOT / "configs" / "ur5.yaml")
    print(f"default reprocess, calibration only (no report files); one BLAS thread; median of {args.repeats}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    cases = [(f"simulated UR5 cell, {n} calib + 100 test points", simulated(cell, n), TARGETS_S[n]) for n in TARGETS_S]
    cases.append(("public UR5 campaign, 1000 calib + 20 test points",
                  import_target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                                    UR5 / "3D_UR5_uncalibrated_random_cleaned.csv"), TARGETS_S[1000]))
    calibrate_dataset(cases[0][1], cell)                                    # imports, caches: not part of the figure
    for label, ds, target in cases:
        wall, cpu, rep = timed(ds, cell, args.repeats)
        eff = ",".join(e["name"] for e in rep.effects.fitted) or "none"
        print(f"  {label:50s} wall {wall:6.2f} s, CPU {cpu:6.2f} s (target <= {target:g} s); "
              f"effects {eff}; layer {rep.method.residual}; final test RMS {rep.final.test.rms_mm:.4f} mm")
    likelihood_unit()


if __name__ == "__main__":
    main()
