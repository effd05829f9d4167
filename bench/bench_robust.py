"""Robust estimation that cannot eat structure: the default pipeline (LM + measurement-fault screen + effects and
residual layer chosen by CV) against plain LM and robust ridge + IGG3, on simulated IRB 2600 campaigns shaped like
real ones: the plan's grid (dense, fixed tool direction) plus 10 calibration and 6 test poses sampled sparsely at
extreme configurations (|J1| 100-150 deg, J2 leaning far back). Each scenario over several seeds:

  A. geometric-only truth, no gross faults;
  B. geometric-only truth, 5 % isolated gross faults of 1-3 mm on grid points;
  C. strong joint compliance (J2/J3, 4x the typical value): the extreme poses carry structure a geometric model
     cannot fit (what IGG3 rejects, and a screen that ignores distance would too);
  D. C + 5 % isolated gross faults;
  E. C + a sag outside the effect library (0.3 mm x (horizontal reach / 1 m)^2): structure no model here fits,
     largest at the sparse extreme poses.

Printed per scenario: held-out test RMS and max (mean over seeds, mm) of each estimator, the worst ratio
default / plain LM, the points each excludes (how many were corrupted, how many sparse), and the effects taken.
Run: python bench/bench_robust.py [SEEDS]   (default 5 seeds; about two minutes on one core)
"""
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from robocal.identify.identification import CalibrationOptions, calibrate  # noqa: E402
from robocal.kinematics.models import smr_tracker  # noqa: E402
from tests.campaign.screen_campaigns import CELL, KIN0, sparse_campaign  # noqa: E402


def baseline(ds, options):
    q, p = np.radians(ds.q_deg), ds.p_tracker_mm
    cal, test = ds.mask("calib"), ds.mask("test")
    res = calibrate(KIN0, q[cal], p[cal], CELL.covariance(p[cal]), options)
    e = np.linalg.norm(p[test] - smr_tracker(res.kinematics, q[test]), axis=1)
    return e, np.flatnonzero(cal)[res.point_weights == 0]


def scenario(name, seeds, **kw):
    rows = {"default": [], "plain LM": [], "robust ridge + IGG3": []}
    excl = {k: [0, 0, 0] for k in rows}
    n_bad, taken = 0, {}
    for s in seeds:
        c = sparse_campaign(s, **kw)
        n_bad += int(c.fault.sum())
        rep = calibrate_dataset(c.ds, CELL).report
        t = rep.final.test
        rows["default"].append((t.rms_mm, t.max_mm))
        ids = {e.point_id for e in rep.excluded_points}
        idx = [i for i, pid in enumerate(c.ds.point_id) if pid in ids]
        excl["default"] = [a + b for a, b in zip(excl["default"], (len(idx), c.fault[idx].sum(), c.sparse[idx].sum()))]
        for e in rep.effects.selection["taken"]:
            taken[e] = taken.get(e, 0) + 1
        for key, opt in (("plain LM", CalibrationOptions(method="lm")),
                         ("robust ridge + IGG3", CalibrationOptions(method="robust_ridge", weights="igg3"))):
            e, rej = baseline(c.ds, opt)
            rows[key].append((float(np.sqrt(np.mean(e**2))), float(e.max())))
            excl[key] = [a + b for a, b in zip(excl[key], (len(rej), c.fault[rej].sum(), c.sparse[rej].sum()))]
    ratio = np.array(rows["default"])[:, 0] / np.array(rows["plain LM"])[:, 0]
    print(f"{name} ({len(seeds)} seeds, {n_bad} corrupted points in all)")
    for key, v in rows.items():
        v = np.array(v)
        print(f"   {key:>20s}: test RMS {v[:, 0].mean():.4f} mm, max {v[:, 1].mean():.3f} mm; excluded "
              f"{excl[key][0]:4d} points, {excl[key][1]} corrupted, {excl[key][2]} sparse")
    print(f"   default / plain LM RMS per seed: max {ratio.max():.3f}, median {np.median(ratio):.3f}; effects taken "
          f"{taken or 'none'}")


def main():
    seeds = range(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
    scenario("A. geometric-only, no gross faults", seeds, compliance_scale=0.0)
    scenario("B. geometric-only, 5 % gross faults 1-3 mm", seeds, compliance_scale=0.0, fault_fraction=0.05)
    scenario("C. joint compliance x4, no gross faults", seeds, compliance_scale=4.0)
    scenario("D. joint compliance x4, 5 % gross faults 1-3 mm", seeds, compliance_scale=4.0, fault_fraction=0.05)
    scenario("E. joint compliance x4 + sag outside the library", seeds, compliance_scale=4.0, sag_mm_at_1m=0.3)


if __name__ == "__main__":
    main()
