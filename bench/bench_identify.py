"""Identification time: ~300 points x ~30 parameters on one core (target < 0.5 s). Prints medians."""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal.identify.identification import CalibrationOptions, calibrate  # noqa: E402
from robocal.kinematics.models import ParamLayout  # noqa: E402
from tests.cells import irb2600, irb2600_poses, make_cell, measure  # noqa: E402


def datasets():
    """Seed 000's plan (one fixed SMR orientation) and 300 random poses with an off-axis SMR (all 27 identifiable)."""
    qc, _ = irb2600_poses()
    yield "grid, fixed orientation", irb2600(), qc, (0.3572, 0.2789, 39.4306)
    rng = np.random.default_rng(1)
    q = rng.uniform(np.radians([-90, -40, -90, -150, -100, -150]), np.radians([90, 90, 40, 150, 100, 150]), (300, 6))
    yield "300 random poses", irb2600().with_(p_flange_smr_mm=[30.0, 20.0, 80.0]), q, (30.0, 20.0, 80.0)


def main(repeats: int = 7) -> None:
    for label, kin, qc, smr in datasets():
        print(label)
        bench(kin, qc, smr, repeats)


def bench(kin, qc, smr, repeats) -> None:
    rng = np.random.default_rng(0)
    cell = make_cell(kin, rng, smr=smr)
    p, cov = measure(cell, qc, rng)
    n_candidates = ParamLayout.of(kin).size
    for method in ("robust_ridge", "lm"):
        times, result = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            result = calibrate(kin, qc, p, cov, CalibrationOptions(method=method))
            times.append(time.perf_counter() - t0)
        print(f"  {method:13s} {len(qc)} points, {n_candidates} candidate / {len(result.identified)} identified "
              f"parameters, {result.iterations} iterations: median {np.median(times):.3f} s "
              f"(min {np.min(times):.3f}, max {np.max(times):.3f}) on one core; target < 0.5 s")


if __name__ == "__main__":
    main()
