"""Speed of the joint-error GP layer's fit (``robocal.layers.joint_gp.fit_joint_gp`` with its 5-fold CV, the call
the residual-layer choice makes), as the module does it against the textbook form it replaced, in the same run.

The marginal likelihood needs, at every optimiser step, the Cholesky factor C of the posterior precision B (K, K)
and diag(B^-1). The module factors B with LAPACK ``dpotrf`` in place and inverts the triangle with ``dtrtri``
(K^3/3 flops each); the textbook form (the alternative here) used ``numpy.linalg.cholesky`` and a triangular solve
against the identity (K^3 flops). Both give the same numbers to rounding: the bench prints the largest difference
of the CV errors and of the predictions of the layer fitted on all rows.

Data: the UR5-like arm of ``robocal.simulation.truth_cell`` at seeded random joint angles, cyclic angle errors on
J1-J3 (orders 2-13, 5-40 urad) plus 0.01 mm noise, so that the layer finds curves; 300 and 1000 poses.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_joint_gp_fit.py [--repeats 5]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np
from scipy.linalg import cho_solve, solve_triangular

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import robocal.layers.joint_gp as jg  # noqa: E402
from robocal.simulation.truth_cell import small_arm_nominal  # noqa: E402


def textbook_posterior(g, lam, var):
    """The replaced form of ``joint_gp._posterior``."""
    B = g.PtP / var + np.diag(1.0 / lam)
    C = np.linalg.cholesky(B)
    return C, cho_solve((C, True), g.Pty / var)


def textbook_inverse(C, lower):
    """The replaced form of the triangle's inverse in ``joint_gp._nll``: a triangular solve of the identity."""
    return solve_triangular(C, np.eye(len(C)), lower=bool(lower)), 0


def data(n: int, seed: int = 0):
    kin = small_arm_nominal()
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, size=(n, 6))
    curves = (15e-6 * np.sin(2 * q[:, 0]) + 8e-6 * np.sin(13 * q[:, 0] + 0.4), 40e-6 * np.sin(3 * q[:, 1] + 1.0),
              5e-6 * np.sin(7 * q[:, 2]))
    A = jg.joint_directions(kin, q, np.arange(3))                     # (n, 3, 3) mm/rad
    e = np.einsum("nij,jn->ni", A, np.array(curves)) + rng.normal(0.0, 0.01, (n, 3))
    return kin, q, e, np.arange(n) % 5


def fit(kin, q, e, fold):
    t0 = time.perf_counter()
    layer, err = jg.fit_joint_gp(kin, q, e, 0.02, fold)
    return time.perf_counter() - t0, layer, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print("joint GP layer fit with 5-fold CV, median wall time of --repeats (interleaved); module vs textbook form")
    for n in (300, 1000):
        kin, q, e, fold = data(n)
        walls = {"module": [], "textbook": []}
        out = {}
        for _ in range(args.repeats):
            walls["module"].append((r := fit(kin, q, e, fold))[0])
            out["module"] = r
            with mock.patch.object(jg, "_posterior", textbook_posterior), \
                    mock.patch.object(jg, "dtrtri", textbook_inverse):
                walls["textbook"].append((r := fit(kin, q, e, fold))[0])
            out["textbook"] = r
        a, b = (float(np.median(walls[k])) for k in ("module", "textbook"))
        d_err = float(np.max(np.abs(out["module"][2] - out["textbook"][2])))
        d_fit = float(np.max(np.abs(out["module"][1].predict(q) - out["textbook"][1].predict(q))))
        cv = float(np.sqrt(np.mean(np.sum(out["module"][2] ** 2, axis=1))))
        print(f"{n:5d} poses, K = {sum(out['module'][1].basis.sizes)} weights: module {a:.2f} s, textbook {b:.2f} s, "
              f"ratio {a / b:.2f}; CV RMS {cv:.4f} mm; largest difference: CV errors {d_err:.1e} mm, "
              f"layer on all rows {d_fit:.1e} mm")


if __name__ == "__main__":
    main()
