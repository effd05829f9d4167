"""The learning-curve figure of docs/planning.md: held-out RMS against the number of calibration poses on the public
UR5 campaign, for the adaptive replay (``campaign select --adaptive``), the one-shot ``campaign select`` and random
subsets (median of 5), against all 1000 rows, with the forecast from the noise model and the parameter priors for the
adaptive order. Writes docs/figures/adaptive_learning_curve.png and prints the figures it plots.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_learning_curve.py [--out PNG]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from campaign.calibrate.selection import select_rows  # noqa: E402
from campaign.plan.learning import forecast_rms  # noqa: E402
from select_forms import ur5_dataset  # noqa: E402
from select_replay import held_out_rms, subset_rms  # noqa: E402

SIZES = (30, 40, 50, 60, 80, 100, 150, 200)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "adaptive_learning_curve.png")
    args = ap.parse_args()
    ds, cell = ur5_dataset()
    cal = np.flatnonzero(ds.mask("calib"))
    everything = held_out_rms(ds, cell)
    sel = adaptive_rows(ds, cell, max(SIZES))
    curves = {"adaptive (select --adaptive)": [subset_rms(ds, cell, sel.order[:n]) for n in SIZES],
              "one-shot (select)": [subset_rms(ds, cell, np.flatnonzero(select_rows(ds, cell, n).keep
                                                                         & ds.mask("calib"))) for n in SIZES],
              "random, median of 5": [float(np.median([subset_rms(ds, cell, np.random.default_rng(s).choice(
                  cal, n, replace=False)) for s in range(5)])) for n in SIZES]}
    fc = forecast_rms(cell, np.radians(ds.q_deg[sel.order]), np.radians(ds.q_deg[ds.mask("test")]), SIZES)
    print(f"public UR5 campaign: held-out RMS (20 random poses) of all {len(cal)} rows {everything:.4f} mm")
    print(f"{'poses':>6s}" + "".join(f"{k[:22]:>24s}" for k in curves) + f"{'forecast (adaptive order)':>28s}")
    for i, n in enumerate(SIZES):
        print(f"{n:6d}" + "".join(f"{v[i]:24.4f}" for v in curves.values()) + f"{fc[i]:28.4f}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.0, 4.2), dpi=110)
    for (label, v), style in zip(curves.items(), ("o-", "s--", "^:")):
        ax.plot(SIZES, v, style, label=label)
    ax.plot(SIZES, fc, "k-.", lw=1, label="forecast: noise model + priors (adaptive order)")
    ax.axhline(everything, color="grey", lw=1, label=f"all {len(cal)} rows")
    ax.set_xlabel("calibration poses")
    ax.set_ylabel("held-out RMS, mm (20 random poses)")
    ax.set_title("Public UR5 campaign: held-out RMS against the number of poses")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
