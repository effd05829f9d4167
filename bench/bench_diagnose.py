"""Diagnosis time, the full self-check on truth campaigns, read-back lag vs backlash and compliance vs gear.

1. Time to diagnose 1000 points (700 calibration + 300 test poses, plus the repeat burst) with the whole candidate
   library, on a truth campaign (robocal/truth.py) carrying compliance, backlash, a read-back lag and a warm-up;
   median wall and CPU time over repeats on one core (target <= 5 s), and the speed-up of the sparse structure
   test against the per-permutation loop it replaced, in the same run.
2. The full self-check (``campaign diagnose --self-check``) on truth campaigns: N seeds per effect (``--seeds``),
   2N effect-free controls, 2N two-effect cases, N out-of-library cases; confusion matrix, named-right rate,
   spurious acceptances per 20 datasets, shrinkage-prediction error.
3. Read-back lag vs backlash on 10 seeds each (read-back joints only, random move order), and gravity compliance
   with a q3-dependent J2 torque vs a J2 gear harmonic.
4. ``--robustness``: misspecified and incomplete data on the older simulator (robocal.selfcheck.simulate_campaign).

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
from scipy.spatial import cKDTree  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal.diagnose import diagnose, structure_test  # noqa: E402
from robocal.effects import DEFAULT_LINK_MASSES_KG, lumped_gravity_torques  # noqa: E402
from robocal.frames import transform_points  # noqa: E402
from robocal.kinematics import chain, smr_tracker  # noqa: E402
from robocal.selfcheck import Protocol, format_confusion, run_self_check, simulate_campaign, truth_input  # noqa: E402
from robocal.truth import TruthProtocol, simulate  # noqa: E402

ROBOT = ("joint_compliance", "backlash", "readback_lag", "thermal_drift")


def _loop_structure_test(w, F, rng, k=10, permutations=200):
    """The per-permutation loop the sparse structure test replaced (for the speed ratio)."""
    m = len(w)
    perms = np.stack([rng.permutation(m) for _ in range(permutations)])
    F = (F - F.mean(axis=0)) / F.std(axis=0)
    _, nn = cKDTree(F).query(F, k=k + 1)
    nn = nn[:, 1:]
    return np.array([np.mean(np.sum(w[pp] * w[pp][nn].mean(axis=1), axis=1)) for pp in perms])


def bench_time(repeats: int = 5) -> None:
    camp = simulate(ROBOT, seed=7, protocol=TruthProtocol(n_calib=700, n_test=300, nest_every=20), scale=1.0)
    inp = truth_input(camp)
    wall, cpu, d = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        d = diagnose(inp)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    n_cal, n_test = int(inp.calib.sum()), int(inp.test.sum())
    print(f"diagnosis of {n_cal} calibration + {n_test} test points ({n_cal + n_test} in all), whole library, truth "
          f"{', '.join(t.name + (' J' + ','.join(map(str, t.joints)) if t.joints else '') for t in camp.truths)}:")
    print(f"  median wall {np.median(wall):.2f} s (min {np.min(wall):.2f}), median CPU {np.median(cpu):.2f} s, "
          f"one thread; target <= 5 s")
    print("  accepted: " + ", ".join(f"{f.effect} J{','.join(map(str, f.joints))}" if f.joints else f.effect
                                     for f in d.findings if f.accepted))
    print(f"  test RMS: geometric {d.baseline_test_rms_mm:.3f} mm -> final {d.final_test_rms_mm:.3f} mm "
          f"(noise floor {d.noise_floor_mm:.3f} mm from {d.noise_floor_source}); unexplained: {d.unexplained}")
    for s in d.stages:
        print(f"    {s['added']:<34s} test RMS {s['test_rms_mm']:.4f} mm, CV RMS {s['cv_rms_mm']:.4f} mm")
    bench_campaign_time(camp, repeats)
    rng = np.random.default_rng(0)
    w, F = rng.standard_normal((1000, 3)), rng.uniform(size=(1000, 6))
    t_new, t_old = [], []
    for _ in range(3):
        t0 = time.process_time()
        structure_test(w, {"x": F}, np.random.default_rng(1))
        t_new.append(time.process_time() - t0)
        t0 = time.process_time()
        _loop_structure_test(w, F, np.random.default_rng(1))
        t_old.append(time.process_time() - t0)
    print(f"  structure test (1000 points, 200 permutations, one space): sparse {np.median(t_new) * 1e3:.0f} ms vs "
          f"loop {np.median(t_old) * 1e3:.0f} ms (x{np.median(t_old) / np.median(t_new):.1f})")


def bench_campaign_time(camp, repeats: int) -> None:
    """`campaign diagnose` on the same campaign written as an interchange CSV: reading, plausibility, the baseline
    geometric fit of reprocess (configured estimator + fault screen) and the diagnosis."""
    import tempfile

    import yaml

    from campaign.config import load_config
    from campaign.diagnose import diagnose_source
    from campaign.interchange import Dataset, write_csv

    with tempfile.TemporaryDirectory() as tmp:
        ds = Dataset(camp.point_id, camp.sets, np.degrees(camp.q_read_rad), camp.p_mm, t_s=camp.t_s,
                     payload_kg=camp.payload_kg)
        csv = Path(tmp) / "campaign.csv"
        write_csv(csv, ds)
        doc = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "irb2600.yaml").read_text())
        doc["tool"]["p_flange_smr_mm"] = [float(x) for x in camp.nominal.p_flange_smr_mm]
        doc["output"] = {"dir": tmp}
        (Path(tmp) / "cfg.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        cfg = load_config(Path(tmp) / "cfg.yaml")
        wall, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            rep = diagnose_source(csv, cfg).report
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    print(f"  campaign diagnose on the CSV (read, baseline geometric fit, diagnosis): median wall "
          f"{np.median(wall):.2f} s, median CPU {np.median(cpu):.2f} s; baseline {rep['baseline_test_rms_mm']:.3f} "
          f"-> final {rep['final_test_rms_mm']:.3f} mm")


def bench_self_check(seeds: int) -> None:
    def progress(i, n, trial):
        if i % 10 == 0 or i == n:
            print(f"  {i}/{n} trials", flush=True)

    result = run_self_check(seeds, progress=progress)
    s = result.summary()
    print("\nconfusion matrix (single effects and controls; columns = first accepted effect):")
    print(format_confusion(result))
    print(f"\nsingle effects: {s['named_right']}/{s['single_trials']} named right (the truth, or in the named "
          f"confusable class); first accepted = truth {s['primary_correct']}, exact set {s['exact_set']}, joints right "
          f"{s['joints_ok']}")
    for name, v in s["per_effect"].items():
        print(f"  {name:20s} {v['named_right']}/{v['n']} (first {v['primary_correct']}, exact {v['exact']}, "
              f"joints {v['joints_ok']})")
    print(f"effect-free controls: {s['controls_clean']}/{s['controls']} with no effect accepted, "
          f"{s['controls_unexplained']} flagged unexplained")
    print(f"two-effect cases: {s['combo_exact']}/{s['combo_trials']} exact, recall {s['combo_recall']:.2f}, "
          f"precision {s['combo_precision']:.2f}")
    print(f"outside the library (reach sag): {s['outside_unexplained']}/{s['outside_trials']} flagged unexplained, "
          f"{s['outside_spurious']} spurious acceptances")
    print(f"spurious acceptances: {s['spurious_acceptances']} in {s['datasets']} datasets = "
          f"{s['spurious_per_20']:.2f} per 20 (target <= 1)")
    e = s["shrinkage_error_mm"]
    print(f"shrinkage predicted (calibration CV) - achieved (test), {e['n']} accepted true effects: mean "
          f"{e['mean']:+.4f} mm, mean |error| {e['mean_abs']:.4f} mm, max |error| {e['max_abs']:.4f} mm "
          f"(mean achieved {e['mean_achieved']:.4f} mm)")
    for t in result.trials:
        if (t.kind == "single" and not t.named_right) or t.spurious or (t.kind == "control" and t.diagnosed):
            print(f"  {t.kind} seed {t.seed} [{t.setting}]: truth "
                  f"{[(x.name, x.joints, x.form) for x in t.truths]} -> {list(zip(t.diagnosed, t.diagnosed_joints))}")
    print(f"{len(result.trials)} trials in {s['seconds']:.0f} s ({s['seconds_per_trial']:.2f} s per diagnosis); "
          f"done-when {'met' if result.passed() else 'NOT met'}")


def bench_lag_backlash(seeds: int = 10) -> None:
    print("\nread-back lag vs backlash (read-back joints only, random move order, no timestamps):")
    pr = TruthProtocol(timestamps=False)
    for truth, other in (("readback_lag", "backlash"), ("backlash", "readback_lag")):
        right = 0
        for s in range(seeds):
            d = diagnose(truth_input(simulate([truth], 2000 + s, pr)))
            acc = {f.effect for f in d.findings if f.accepted}
            right += truth in acc and other not in acc
        print(f"  truth {truth}: {right}/{seeds} with {truth} accepted and {other} not")
    right = 0
    for s in range(seeds):
        d = diagnose(truth_input(simulate(["readback_lag"], 2100 + s, pr), with_qc=True))
        f = next(f for f in d.findings if f.effect == "readback_lag")
        right += f.accepted and "direct_comparison" in f.evidence
    print(f"  with commanded joints (direct comparison): {right}/{seeds} lags accepted with the measured lag")


def bench_compliance_gear(seeds: int = 10) -> None:
    print("\ngravity compliance (J2 torque depends on q3) vs a J2 gear harmonic:")
    comp = gear2 = cls = 0
    for s in range(seeds):
        d = diagnose(truth_input(simulate(["joint_compliance"], 2200 + s, TruthProtocol())))
        acc = [f for f in d.findings if f.accepted]
        comp += any(f.effect == "joint_compliance" for f in acc)
        g = [f for f in acc if f.effect == "gear_cyclic" and 2 in f.joints]
        gear2 += bool(g)
        cls += bool(g) and any(c["effect"] == "joint_compliance" for c in g[0].evidence.get("confusable_with", []))
    print(f"  compliance accepted {comp}/{seeds}; gear J2 accepted {gear2}/{seeds} "
          f"(of which named in one class with compliance: {cls})")


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
    bench_lag_backlash()
    bench_compliance_gear()
    if not args.no_self_check:
        bench_self_check(args.seeds)
    if args.robustness:
        bench_robustness(args.robustness)


if __name__ == "__main__":
    main()
