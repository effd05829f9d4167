"""Diagnosis time and the full withheld-effect self-check.

1. Time to diagnose a 400-point campaign (300 calibration + 100 test poses, plus the repeat burst) with the
   whole candidate library, on a robot carrying five effects at once (the most selection steps); target <= 60 s.
2. The full self-check (``campaign diagnose --self-check``): 5 seeds per effect (``--seeds N``), 2N effect-free
   controls and 2N two-effect cases; prints the confusion matrix, the shrinkage-prediction error and the time.
3. ``--robustness``: misspecified and incomplete data (noise 2x the specs, heavy tails, outliers, effects outside
   the library: link bending, base compliance, tracker scale; missing timestamps / approach directions / second
   payload), per seed.

    python bench/bench_diagnose.py [--seeds N] [--no-self-check] [--robustness SEEDS]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal.diagnose import diagnose  # noqa: E402
from robocal.effects import DEFAULT_LINK_MASSES_KG, lumped_gravity_torques  # noqa: E402
from robocal.frames import transform_points  # noqa: E402
from robocal.kinematics import chain, smr_tracker  # noqa: E402
from robocal.selfcheck import Protocol, format_confusion, run_self_check, simulate_campaign  # noqa: E402

ROBOT = ("joint_compliance", "gear_cyclic", "backlash", "thermal_drift", "axis_coupling")


def bench_time(repeats: int = 3) -> None:
    camp = simulate_campaign(ROBOT, seed=7, magnitude=1.0)
    inp = camp.diagnosis_input()
    times, d = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        d = diagnose(inp)
        times.append(time.perf_counter() - t0)
    n_cal, n_test = int(inp.calib.sum()), int(inp.test.sum())
    print(f"diagnosis of {n_cal} calibration + {n_test} test points ({n_cal + n_test} in all), whole library "
          f"(12 candidates), truth {', '.join(t.name + (' J' + ','.join(map(str, t.joints)) if t.joints else '') for t in camp.truths)}:")
    print(f"  median {np.median(times):.2f} s (min {np.min(times):.2f}, max {np.max(times):.2f}) on one core; "
          f"target <= 60 s")
    print("  accepted: " + ", ".join(f"{f.effect} J{','.join(map(str, f.joints))}" if f.joints else f.effect
                                     for f in d.findings if f.accepted))
    print(f"  test RMS: geometric {d.baseline_test_rms_mm:.3f} mm -> final {d.final_test_rms_mm:.3f} mm "
          f"(noise floor {d.noise_floor_mm:.3f} mm from {d.noise_floor_source}); unexplained: {d.unexplained}")
    for s in d.stages:
        print(f"    {s['added']:<34s} test RMS {s['test_rms_mm']:.4f} mm, CV RMS {s['cv_rms_mm']:.4f} mm")


def bench_self_check(seeds: int) -> None:
    def progress(i, n, trial):
        if i % 10 == 0 or i == n:
            print(f"  {i}/{n} trials", flush=True)

    result = run_self_check(seeds, progress=progress)
    s = result.summary()
    print("\nconfusion matrix (single effects and controls; columns = first accepted effect):")
    print(format_confusion(result))
    print(f"\nsingle effects: {s['primary_correct']}/{s['single_trials']} correctly attributed "
          f"(exact set {s['exact_set']}, joints right {s['joints_ok']})")
    for name, v in s["per_effect"].items():
        print(f"  {name:20s} {v['primary_correct']}/{v['n']} (exact {v['exact']}, joints {v['joints_ok']})")
    print(f"effect-free controls: {s['controls_clean']}/{s['controls']} with no effect accepted, "
          f"{s['controls_unexplained']} flagged unexplained")
    print(f"two-effect cases: {s['combo_exact']}/{s['combo_trials']} exact, recall {s['combo_recall']:.2f}, "
          f"precision {s['combo_precision']:.2f}")
    e = s["shrinkage_error_mm"]
    print(f"shrinkage predicted (calibration CV) - achieved (test), {e['n']} accepted true effects: mean "
          f"{e['mean']:+.4f} mm, mean |error| {e['mean_abs']:.4f} mm, max |error| {e['max_abs']:.4f} mm "
          f"(mean achieved {e['mean_achieved']:.4f} mm)")
    missed = [t for t in result.trials if t.kind == "single" and t.primary != t.truth_names[0]]
    for t in missed:
        tr = t.truths[0]
        print(f"  miss: {tr.name} ({tr.form}, joints {tr.joints}, visible {tr.visible_rms_mm:.4f} mm) -> {t.primary}")
    print(f"{len(result.trials)} trials in {s['seconds']:.0f} s ({s['seconds_per_trial']:.2f} s per diagnosis); "
          f"done-when {'met' if result.passed() else 'NOT met'}")


# ---------------------------------------------------------------- misspecified / incomplete data
def _remeasure(camp, extra_dp=None, noise=None, seed=0):
    """The campaign's poses measured again with an extra displacement and/or another noise distribution."""
    rng = np.random.default_rng(seed)
    meta = {"t_s": camp.t_s, "payload_kg": camp.payload_kg, "approach": camp.approach}
    p = camp.cell.true_smr_tracker(camp.q_rad, meta)
    if extra_dp is not None:
        p = p + extra_dp(camp.cell.truth, camp.q_rad, meta)
    z = rng.standard_normal(p.shape) if noise is None else noise(rng, p.shape)
    return replace(camp, p_mm=p + np.einsum("nij,nj->ni", np.linalg.cholesky(camp.cov_mm2), z))


def _without_repeats(camp):
    keep = np.array([s != "check" for s in camp.sets])
    return replace(camp, q_rad=camp.q_rad[keep], p_mm=camp.p_mm[keep], cov_mm2=camp.cov_mm2[keep],
                   sets=tuple(np.array(camp.sets)[keep]), point_id=tuple(np.array(camp.point_id)[keep]),
                   t_s=camp.t_s[keep], payload_kg=camp.payload_kg[keep], approach=camp.approach[keep])


def _bending(kin, q, meta):
    """Euler-Bernoulli link bending: the distal chain translated perpendicular to upper arm and forearm."""
    c = chain(kin, q, full=False)
    tau = lumped_gravity_torques(kin, q, DEFAULT_LINK_MASSES_KG, 0.5, 0.0, meta["payload_kg"])
    dp = np.zeros((len(q), 3))
    for j, (a, b) in ((1, (1, 2)), (2, (2, 4))):
        perp = np.cross(c.axis[:, a], c.origin[:, b] - c.origin[:, a])
        dp -= 0.5 * (tau[:, j] * 3e-4)[:, None] * perp / np.linalg.norm(perp, axis=1, keepdims=True)
    return dp @ kin.T_tracker_base[:3, :3].T


def _base_compliance(kin, q, meta):
    """The base tilting about a horizontal axis by the overturning moment."""
    c = chain(kin, q, full=False)
    tau = lumped_gravity_torques(kin, q, DEFAULT_LINK_MASSES_KG, 0.5, 0.0, meta["payload_kg"])
    p = transform_points(c.T_base_flange, kin.p_flange_smr_mm)
    return ((tau[:, 1] * 1.5e-7)[:, None] * np.cross(c.axis[:, 1], p)) @ kin.T_tracker_base[:3, :3].T


def robustness_cases(s: int):
    c0 = simulate_campaign([], 500 + s)
    ct = simulate_campaign(["thermal_drift"], 600 + s)
    cb = simulate_campaign(["backlash"], 700 + s)
    cp = simulate_campaign(["payload_deflection"], 800 + s, protocol=Protocol(payloads_kg=(12.0,)))
    cc = simulate_campaign(["joint_compliance"], 900 + s, protocol=Protocol(payloads_kg=(0.0,)))
    return [
        ("no effect, noise 2x the specs, no repeats (floor from specs)",
         _without_repeats(_remeasure(c0, noise=lambda r, sh: 2.0 * r.standard_normal(sh), seed=s)), None),
        ("no effect, Student-t (3 dof) noise", _remeasure(c0, noise=lambda r, sh: r.standard_t(3, sh) / np.sqrt(3),
                                                          seed=s), None),
        ("no effect, 1 % outliers of 0.3 mm", _remeasure(
            c0, noise=lambda r, sh: r.standard_normal(sh) + (r.random(sh[:1]) < 0.01)[:, None] * r.normal(0, 10, sh),
            seed=s), None),
        ("link bending (not in the library)", _remeasure(c0, extra_dp=_bending, seed=s), None),
        ("base compliance (not in the library)", _remeasure(c0, extra_dp=_base_compliance, seed=s), None),
        ("tracker scale +5 ppm (absorbed)", _remeasure(c0, extra_dp=lambda k, q, m: 5e-6 * smr_tracker(k, q), seed=s),
         None),
        ("thermal drift, with timestamps", ct, None),
        ("thermal drift, timestamps withheld", ct, lambda inp: replace(inp, t_s=None)),
        ("backlash, approach directions withheld", cb, lambda inp: replace(inp, approach=None)),
        ("payload deflection, one payload (12 kg)", cp, None),
        ("joint compliance, one payload (0 kg)", cc, None),
    ]


def bench_robustness(seeds: int) -> None:
    print("\nmisspecified or incomplete data (accepted effects; unexplained; what cannot be told):")
    for s in range(seeds):
        for label, camp, mutate in robustness_cases(s):
            inp = camp.diagnosis_input()
            d = diagnose(mutate(inp) if mutate else inp)
            acc = ", ".join(f.effect + (f" J{','.join(map(str, f.joints))}" if f.joints else "")
                            for f in d.findings if f.accepted) or "none"
            und = ", ".join(u["effect"] for u in d.undiagnosable) or "-"
            print(f"  seed {s}: {label}: {acc}; test RMS {d.baseline_test_rms_mm:.3f} -> {d.final_test_rms_mm:.3f} mm "
                  f"(floor {d.noise_floor_mm:.3f}, {d.noise_floor_source}); unexplained {d.unexplained}; "
                  f"cannot tell: {und}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--no-self-check", action="store_true")
    ap.add_argument("--robustness", type=int, default=0, metavar="SEEDS")
    args = ap.parse_args()
    bench_time()
    if not args.no_self_check:
        bench_self_check(args.seeds)
    if args.robustness:
        bench_robustness(args.robustness)


if __name__ == "__main__":
    main()
