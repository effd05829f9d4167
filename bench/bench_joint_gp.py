"""Whether ``calibration.residual: auto`` should offer the joint-error GP layer (``robocal.layers.joint_gp``), judged by
held-out prediction.

The layer reads the residual as one smooth angle-error curve per joint, moved to the SMR through the Jacobian. It
was written after the UR5 campaign's residual showed cyclic errors of many orders on J1-J3 (``bench_scan.py
--periodogram``), so the UR5 columns are where the idea came from, not an independent test; the simulated forms
are (none was changed after seeing them).

Protocol (fixed before the first run): every data set is calibrated by the DEFAULT ``process`` of its config with
the layer candidates none / IDW / GPR, and with none / IDW / GPR / joint GP (the same one-standard-error rule picks
among them); the score is the held-out RMS with the joint GP offered over that without; per form the mean ratio,
and the mean over the forms. Data sets as in ``bench_scan.py``: the public UR5 campaign (all 1000 grid rows and 10
seeded random 100-row subsets, its 20 random held-out poses), the UR5 split (a seeded half of the grid as
calibration rows, 520 poses held out; all 500 rows and 3 random 100-row subsets per split), the simulated cells of
``bench_select.py`` and ``bench_layer_rule.py`` (seeds 1 2 3; all grid rows and 3 random thirds) and the demo cell's
mock runs with order-dependent errors (drift a joint-space layer could mistake for structure). The last column is
the layer kept with the joint GP offered.

Decision rule: the joint GP is offered if the mean over the forms is below 1, no simulated form's mean is above
1.02, and the large real held-out set gains (``ur5-split`` mean below 1).

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_joint_gp.py [--seeds 1 2 3] [--forms ...] [--time]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import robocal.layers.choice as layers  # noqa: E402
from bench_layer_rule import TRUTH  # noqa: E402
from bench_scan import ablation, ablation_parser  # noqa: E402
from bench_select import ur5_dataset  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402

OFFERED = layers.LAYER_KINDS
WITHOUT = tuple(k for k in OFFERED if k != "joint_gp")


def held_out(ds, cell) -> list[tuple[float, str]]:
    """(held-out RMS mm, layer kept) of the default calibration of ``ds`` without and with the joint GP offered."""
    out = []
    try:
        for kinds in (WITHOUT, OFFERED):
            layers.LAYER_KINDS = kinds
            rep = calibrate_dataset(ds, cell).report
            out.append((float(rep.final.test.rms_mm), rep.residual_choice.chosen))
    finally:
        layers.LAYER_KINDS = OFFERED
    return out


def timing(repeats: int = 3) -> None:
    """Median wall time of the UR5 campaign's default calibration without and with the joint GP offered."""
    ds, cell = ur5_dataset(None)
    walls = {}
    for label, kinds in (("without", WITHOUT), ("with", OFFERED)):
        layers.LAYER_KINDS = kinds
        walls[label] = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            calibrate_dataset(ds, cell)
            walls[label].append(time.perf_counter() - t0)
    layers.LAYER_KINDS = OFFERED
    a, b = (float(np.median(walls[k])) for k in ("without", "with"))
    print(f"UR5 campaign (1000 + 20 rows), default calibration, median of {repeats}: without the joint GP {a:.2f} s, "
          f"with {b:.2f} s (ratio {b / a:.2f})")


def main() -> None:
    args = ablation_parser(__doc__, "the layer", extra=(TRUTH,)).parse_args()
    if args.time:
        timing()
        return
    print("held-out RMS (mm) of the default process without and with the joint GP offered; ratio; layer kept")
    print(f"{'form':26s}{'data set':>16s}{'without':>10s}{'with':>10s}{'ratio':>8s}  layer", flush=True)
    keep, text = ablation(args.forms, args.seeds, held_out, lambda a, b: f"  {a[1]} -> {b[1]}")
    print(text + (": offer the joint GP" if keep else ": do not offer the joint GP"))


if __name__ == "__main__":
    main()
