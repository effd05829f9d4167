"""Robust estimation that cannot eat structure: the default pipeline (LM + local measurement-fault screen +
effects and residual layer chosen by CV) against plain LM and robust ridge + IGG3, on simulated IRB 2600
campaigns of random configurations (not the plan's grid), each scenario over several seeds:

  A. geometric-only truth, no gross outliers;
  B. geometric-only truth, 5 % isolated gross outliers of 1-3 mm;
  C. strong joint compliance (J2/J3, 4x the typical value) in the truth, no gross outliers: the high-torque poses
     carry structure a geometric model cannot fit (what IGG3 rejects);
  D. C + 5 % isolated gross outliers.

Printed per scenario: held-out test RMS (mean over seeds, mm) of each estimator, the worst ratio default / plain LM,
the points each excludes (and how many of them were corrupted), and the effects the default takes.
Run: python bench/bench_robust.py   (about a minute on one core)
"""
import os
import sys
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from campaign.cell import measurement_covariance, nominal_kinematics, simulated_cell  # noqa: E402
from campaign.config import load_config  # noqa: E402
from campaign.interchange import Dataset  # noqa: E402
from campaign.process import process  # noqa: E402
from robocal.effects import joint_compliance  # noqa: E402
from robocal.identify import CalibrationOptions, calibrate  # noqa: E402
from robocal.kinematics import smr_tracker  # noqa: E402
from robocal.simulate import random_geometric_errors  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CFG = load_config(ROOT / "configs/irb2600.yaml")
N_CAL, N_TEST = 150, 60
LO, HI = np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180])


def campaign(seed, compliance_scale=0.0, outliers=0.0):
    rng = np.random.default_rng(seed)
    base = simulated_cell(CFG)
    effects = ((joint_compliance((2, 3)), compliance_scale * np.array([3.3e-7, 6.7e-7])),) if compliance_scale else ()
    cell = replace(base, truth=random_geometric_errors(nominal_kinematics(CFG), rng).with_(
        T_tracker_base=base.truth.T_tracker_base, p_flange_smr_mm=base.truth.p_flange_smr_mm), effects=effects)
    q = rng.uniform(LO, HI, (N_CAL + N_TEST, 6))
    meta = {"payload_kg": np.full(len(q), float(CFG.tool.payload_kg or 0.0))}
    p, _ = cell.measure(q, rng, meta)
    bad = np.zeros(len(q), bool)
    k = int(round(outliers * N_CAL))
    if k:
        idx = rng.choice(N_CAL, k, replace=False)
        d = rng.normal(size=(k, 3))
        p[idx] += d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(1.0, 3.0, (k, 1))
        bad[idx] = True
    ds = Dataset(tuple(f"P{i:03d}" for i in range(len(q))), tuple(["calib"] * N_CAL + ["test"] * N_TEST),
                 np.degrees(q), p, source=f"sim{seed}")
    return ds, q, p, bad


def baseline(q, p, options):
    kin0 = nominal_kinematics(CFG)
    cov = measurement_covariance(CFG, p[:N_CAL])
    res = calibrate(kin0, q[:N_CAL], p[:N_CAL], cov, options)
    e = p[N_CAL:] - smr_tracker(res.kinematics, q[N_CAL:])
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1)))), np.flatnonzero(res.point_weights == 0)


def scenario(name, seeds, **kw):
    rows = {"default": [], "plain LM": [], "robust ridge + IGG3": []}
    excl = {k: [0, 0] for k in rows}
    n_bad, taken = 0, {}
    for s in seeds:
        ds, q, p, bad = campaign(s, **kw)
        n_bad += int(bad.sum())
        rep = process(ds, CFG).report
        rows["default"].append(rep["stages"]["compensated"]["test"]["rms_mm"])
        ids = {e["point_id"] for e in rep["excluded_points"]}
        idx = [i for i, pid in enumerate(ds.point_id) if pid in ids]
        excl["default"][0] += len(idx)
        excl["default"][1] += int(bad[idx].sum())
        for e in rep["effects"]["selection"]["taken"]:
            taken[e] = taken.get(e, 0) + 1
        for key, opt in (("plain LM", CalibrationOptions(method="lm")),
                         ("robust ridge + IGG3", CalibrationOptions(method="robust_ridge", weights="igg3"))):
            rms, rej = baseline(q, p, opt)
            rows[key].append(rms)
            excl[key][0] += len(rej)
            excl[key][1] += int(bad[rej].sum())
    ratio = np.array(rows["default"]) / np.array(rows["plain LM"])
    print(f"{name} ({len(seeds)} seeds, {n_bad} corrupted points in all)")
    for key, v in rows.items():
        print(f"   {key:>20s}: test RMS {np.mean(v):.4f} mm (worst seed {np.max(v):.4f}); excluded {excl[key][0]:4d} "
              f"points, {excl[key][1]} of them corrupted")
    print(f"   default / plain LM per seed: max {ratio.max():.3f}, median {np.median(ratio):.3f}; effects taken "
          f"{taken or 'none'}")


def main():
    seeds = range(10)
    scenario("A. geometric-only, no gross outliers", seeds)
    scenario("B. geometric-only, 5 % gross outliers 1-3 mm", seeds, outliers=0.05)
    scenario("C. joint compliance x4, no gross outliers", seeds, compliance_scale=4.0)
    scenario("D. joint compliance x4, 5 % gross outliers 1-3 mm", seeds, compliance_scale=4.0, outliers=0.05)


if __name__ == "__main__":
    main()
