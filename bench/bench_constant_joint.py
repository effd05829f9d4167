"""A joint held at one angle: the pose blocks of the effect selection before and after ``spread_scaled``.

The bug (found on development seed 101 of the UR10-like form, whose grid holds J6 at one angle): the pose blocks
scaled each joint by its spread, and a joint held at one angle has a spread of rounding (9e-15 rad there), not 0.
Divided by it, that joint became the largest coordinate, k-means put every pose in one cluster, and the pose
blocking had a single fold: every candidate's held-out errors there were those of no fit at all, so no effect could
pass the rule that its gain be positive under each blocking, and the effect selection took nothing. The diagnosis's
variogram and neighbour tests scaled the same way, and its test of joints that follow the measurement order read such
a joint. ``robocal.effects.cv.spread_scaled`` now leaves out a column whose spread is rounding (at most 1e-9 x its
magnitude: ``varies``), and centres the others.

This is a fix, kept whatever the figures; the script measures what it changes. For each data set: the sizes of the
pose-block folds of all calibration rows, and the held-out RMS of the default process before (the old scaling,
patched back in) and after, on all rows and on rule ``f``'s 50 and 100 rows. Data: the two config forms of
``select_forms.ADAPTIVE_FORMS`` (grids with J6 held) at seeds 19 20 21 (the seventh protocol's; their all-rows
figures are issue 32's denominators), the public UR5 campaign and one truth form (random poses, every joint moving).

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_constant_joint.py [--seeds 19 20 21]

Figures (run with the fix, before it was committed):
  * UR10-like, seeds 19-21: all rows' pose blocks were one fold of 427 poses, now five of 81-89. Held-out RMS before
    / after: all rows 0.0511 / 0.0510, 0.0557 / 0.0552, 0.0541 / 0.0539 mm (the effect selection now takes the
    form's compliance and J2 gear error on all rows, where it took nothing); ``f``'s 100 rows 0.0551 / 0.0535,
    0.0559 / 0.0550, 0.0564 / 0.0550; ``f``'s 50 rows unchanged.
  * The UR5 campaign, the IRB 4600-like and the compliance + gear + drift forms (seeds 19-21): the same folds and
    every figure the same.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from contextlib import ExitStack, contextmanager
from unittest import mock
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import robocal.diagnose.evidence as evidence  # noqa: E402
import robocal.diagnose.regions as regions  # noqa: E402
import robocal.diagnose.remainder as remainder  # noqa: E402
import robocal.effects.cv as cv  # noqa: E402
from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from select_forms import ADAPTIVE_FORMS, ur5_dataset  # noqa: E402
from select_replay import rms_off_on  # noqa: E402

FORMS = ("UR10-like (compliance + J2 gear)", "IRB 4600-like (compliance + J3 gear + coupling)",
         "compliance+gear+drift")


def _old_scaled(X):
    """The scaling before the fix: every column with a spread above 0 divided by it, not centred."""
    X = np.asarray(X, float).reshape(len(X), -1)
    sd = X.std(axis=0)
    return X[:, sd > 0] / sd[sd > 0]


@contextmanager
def before_fix():
    """The scaling and the test of a varying joint as they were before the fix."""
    with ExitStack() as stack:
        for m in (cv, regions, remainder):
            stack.enter_context(mock.patch.object(m, "spread_scaled", _old_scaled))
        stack.enter_context(mock.patch.object(evidence, "varies", lambda X: np.asarray(X, float).std(axis=0) > 0))
        yield


def folds(ds) -> str:
    q = np.radians(ds.q_deg[ds.mask("calib")])
    with before_fix():
        old = np.bincount(cv.pose_blocks(q, 5, 0))
    return f"pose-block folds before {old.tolist()}, after {np.bincount(cv.pose_blocks(q, 5, 0)).tolist()}"


def figures(ds, cell, rows) -> tuple[float, float]:
    """Held-out RMS (mm) before and after the fix, on the calibration rows ``rows`` (all when None)."""
    return rms_off_on(ds, cell, rows, before_fix)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[19, 20, 21])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        runs = [("UR5 campaign", *ur5_dataset())]
        runs += [(f"{form}, seed {s}", *ADAPTIVE_FORMS[form](Path(tmp), s)) for form in FORMS for s in args.seeds]
        for label, ds, cell in runs:
            print(f"{label}: {folds(ds)}", flush=True)
            order = adaptive_rows(ds, cell, 100, rule="f").order
            for n in (None, 50, 100):
                old, new = figures(ds, cell, None if n is None else order[:n])
                print(f"  {'all rows' if n is None else f'f {n}':8s} before {old:.4f}  after {new:.4f} mm  "
                      f"ratio {new / old:.3f}", flush=True)


if __name__ == "__main__":
    main()
