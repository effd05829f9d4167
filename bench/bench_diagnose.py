"""Diagnosis and effect-engine timing, the self-check on truth campaigns, and both commands on one CSV.

1. Time on 1000 points (700 calibration + 300 test poses of a truth campaign, robocal/simulation/truth_cell.py, carrying
   compliance, backlash, a read-back lag and a warm-up): ``robocal.diagnose.diagnose`` with the error budget, its
   bootstrap, the verdicts and the layer's description (target <= 5 s; the part of it they take is printed), the
   ``campaign diagnose`` path on the same campaign written as a CSV (target <= 5 s), and the default ``reprocess``
   calibration work (with its budget)
   (``campaign.calibrate.stages.calibrate_dataset``: preparation, geometric fit, effect engine, residual layer, evaluation; no HTML;
   target <= 5 s). Medians of wall and CPU time, one thread.
2. The self-check (``campaign diagnose --self-check``): N seeds per effect and per failure-class form, 2N
   controls, 2N two-effect cases, N out-of-library cases; the confusion matrix and one line per form. Then the
   budget forms (``robocal.diagnose.selfcheck_budget``), N seeds each: joint jitter above the declared floor (nothing
   accepted, remainder noise), a reach-dependent J2 sag outside the library (unexplained), compliance + backlash
   (each budget component within 25 % of the simulator's truth).
3. Read-back lag vs backlash (10 seeds each, read-back joints only).
4. ``--csv DATA --config CFG``: reprocess and diagnose on one campaign (e.g. a measured one): both commands'
   accepted effects, parameters and held-out figures side by side.

    python bench/bench_diagnose.py [--seeds N] [--no-self-check] [--csv DATA --config CFG]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal.diagnose.core import diagnose  # noqa: E402
from robocal.diagnose.selfcheck import format_confusion, run_self_check, truth_input  # noqa: E402
from robocal.simulation.truth_cell import TruthProtocol, simulate  # noqa: E402

ROBOT = ("joint_compliance", "backlash", "readback_lag", "thermal_drift")


def _timed(fn, repeats):
    wall, cpu, out = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return out, float(np.median(wall)), float(np.median(cpu))


def bench_time(repeats: int = 3) -> None:
    from robocal.diagnose import core

    camp = simulate(ROBOT, seed=7, protocol=TruthProtocol(n_calib=700, n_test=300), scale=1.0)
    inp = truth_input(camp)
    gap_cpu, inner = [], core.budget_and_verdict

    def timed_gap(*a, **k):
        c0 = time.process_time()
        out = inner(*a, **k)
        gap_cpu.append(time.process_time() - c0)
        return out
    core.budget_and_verdict = timed_gap
    try:
        d, wall, cpu = _timed(lambda: diagnose(inp), repeats)
    finally:
        core.budget_and_verdict = inner
    n_cal, n_test = int(inp.calib.sum()), int(inp.test.sum())
    print(f"diagnosis of {n_cal} calibration + {n_test} test points, truth "
          f"{', '.join(t.name + (' J' + ','.join(map(str, t.joints)) if t.joints else '') for t in camp.truths)}:")
    print(f"  robocal.diagnose with the error budget: median wall {wall:.2f} s, median CPU {cpu:.2f} s (target <= 5 s);"
          f" of which budget + {d.budget.interval.split(' (')[0]} + verdicts + layer description: median CPU "
          f"{float(np.median(gap_cpu)):.2f} s")
    print("  budget: " + ", ".join(f"{c.name} {c.rms_mm:.4f} [{c.low_mm:.4f}-{c.high_mm:.4f}]"
                                   for c in d.budget.components)
          + f"; nominal {d.budget.nominal_rms_mm:.4f} mm, closure {100 * d.budget.closure:.2f} %")
    print("  accepted: " + ", ".join(f.evidence["label"] for f in d.findings if f.accepted))
    for s in d.stages:
        print(f"    {s['added']:<40s} test RMS {s['test_rms_mm']:.4f} mm, CV RMS {s['cv_rms_mm']:.4f} mm")
    print(f"  {d.unexplained_structure['text']}")
    from campaign.config.load import load_cell
    from campaign.calibrate.diagnosis import diagnose_source
    from campaign.data.interchange_csv import read_csv
    from campaign.calibrate.stages import calibrate_dataset
    from tests.campaign.helpers import truth_csv

    with tempfile.TemporaryDirectory() as tmp:
        csv, cfg_path = truth_csv(Path(tmp), camp)
        cell = load_cell(cfg_path)
        rep, wall, cpu = _timed(lambda: diagnose_source(csv, cell).report, repeats)
        print(f"  campaign diagnose on the CSV (read, prepare, geometric fit, engine, diagnosis with the budget): median "
              f"wall {wall:.2f} s, median CPU {cpu:.2f} s (target <= 5 s)")
        ds = read_csv(csv)
        pr, wall, cpu = _timed(lambda: calibrate_dataset(ds, cell), repeats)
        st = pr.report.stages
        print(f"  default reprocess calibration work (process(): prepare, geometric fit, effect engine, residual layer "
              f"{pr.report.residual_choice.chosen}, evaluation; no HTML): median wall {wall:.2f} s, median CPU "
              f"{cpu:.2f} s (target <= 5 s); test RMS kinematic {st['kinematic'].test.rms_mm:.4f} -> elastic "
              f"{st.get('elastic', st['kinematic']).test.rms_mm:.4f} -> compensated "
              f"{st['compensated'].test.rms_mm:.4f} mm (diagnose final {rep['final_test_rms_mm']:.4f} mm)")


def bench_self_check(seeds: int) -> None:
    def progress(i, n, trial):
        if i % 20 == 0 or i == n:
            print(f"  {i}/{n} trials", flush=True)

    result = run_self_check(seeds, progress=progress)
    s = result.summary()
    print("\nconfusion matrix (single effects and controls; columns = first accepted effect), then the forms:")
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
    print(f"read-back lag called backlash: {s['lag_as_backlash']} of {s['lag_trials']} campaigns with a lag")
    print(f"spurious acceptances: {s['spurious_acceptances']} in {s['datasets']} datasets = "
          f"{s['spurious_per_20']:.2f} per 20")
    e = s["shrinkage_error_mm"]
    print(f"shrinkage predicted (calibration CV) - achieved (test), {e['n']} accepted true effects: mean "
          f"{e['mean']:+.4f} mm, mean |error| {e['mean_abs']:.4f} mm, max |error| {e['max_abs']:.4f} mm "
          f"(mean achieved {e['mean_achieved']:.4f} mm)")
    for t in result.trials:
        bad = (t.kind == "single" and not t.named_right) or (t.kind == "control" and t.diagnosed) or \
            (t.kind not in ("single", "control", "combo", "outside") and not t.named_right) or t.lag_as_backlash
        if bad:
            print(f"  {t.kind} seed {t.seed} [{t.setting}]: truth {[(x.name, x.joints, x.form) for x in t.truths]} "
                  f"-> {list(zip(t.diagnosed, t.diagnosed_joints))}, classes {[c for c in t.classes if len(c) > 1]}")
    print(f"{len(result.trials)} trials in {s['seconds']:.0f} s ({s['seconds_per_trial']:.2f} s per diagnosis); "
          f"done-when {'met' if result.passed() else 'NOT met'}")
    bench_budget_forms(seeds)


def bench_budget_forms(seeds: int) -> None:
    from robocal.diagnose.selfcheck_budget import budget_summary, run_budget_check

    def progress(i, n, trial):
        if i % 20 == 0 or i == n:
            print(f"  {i}/{n} budget trials", flush=True)
    t0 = time.perf_counter()
    trials = run_budget_check(seeds, progress=progress)
    s = budget_summary(trials)
    print("\nbudget forms:")
    what = {"jitter": "joint jitter above the floor, no effect: nothing accepted and remainder noise",
            "j2_sag": "reach-dependent J2 sag outside the library: unexplained",
            "budget_pair": "compliance + backlash: each budget component within 25 % of the truth"}
    for kind, v in s.items():
        extra = ""
        if kind == "j2_sag":
            extra = f"; the far reach holds most of the remainder in {v['far_reach_first']}/{v['n']}"
        if kind == "budget_pair":
            extra = f"; median |budget - truth| / truth {100 * v['median_relative_error']:.1f} %"
        if kind == "jitter":
            jn = v["joint_noise_deg"]
            extra = (f"; joint-shaped noise on J1-J3 estimated {jn['median']:.4f} deg (median; {jn['min']:.4f}-"
                     f"{jn['max']:.4f}) against the simulated {jn['truth']:.4f} deg")
        print(f"  {kind:12s} {what[kind]}: {v['passed']}/{v['n']} (target >= {100 * v['target']:.0f} %: "
              f"{'met' if v['met'] else 'NOT met'}); max closure error {100 * v['max_closure']:.2f} %{extra}")
    for t in trials:
        if not t.passed:
            print(f"  {t.kind} seed {t.seed}: accepted {list(t.diagnosed)}, remainder {t.remainder}, unexplained "
                  f"{t.unexplained}, budget {({k: round(v, 4) for k, v in t.budget_mm.items()})}, truth "
                  f"{({k: round(v, 4) for k, v in t.truth_mm.items()})}")
    print(f"{len(trials)} budget trials in {time.perf_counter() - t0:.0f} s")


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


def bench_csv(csv: str, config: str) -> None:
    """Reprocess and diagnose on one campaign: accepted effects, values and held-out figures."""
    from campaign.config.load import load_cell
    from campaign.calibrate.diagnosis import diagnose_dataset
    from campaign.data.interchange_csv import read_csv
    from campaign.calibrate.stages import calibrate_dataset

    cell = load_cell(config)
    t0 = time.process_time()
    rep = calibrate_dataset(read_csv(csv), cell).report
    t1 = time.process_time()
    diag = diagnose_dataset(read_csv(csv), cell).report
    t2 = time.process_time()
    print(f"\n{csv} with {config}:")
    sel = rep.effects.selection
    print(f"  reprocess ({t1 - t0:.2f} s CPU): effects {sel['taken'] if sel else rep.method.effects}")
    for name, st in rep.stages.items():
        print(f"    {name:12s} test mean {st.test.mean_mm:.4f} mm, RMS {st.test.rms_mm:.4f} mm")
    acc = [f for f in diag["findings"] if f["accepted"]]
    print(f"  diagnose ({t2 - t1:.2f} s CPU): accepted {[f['evidence']['label'] for f in acc]}; geometric "
          f"{diag['baseline_test_rms_mm']:.4f} -> final {diag['final_test_rms_mm']:.4f} mm RMS")
    for f in acc:
        ev = f["evidence"]
        print(f"    {ev['label']}: held-out {ev['cv_rms_before_mm']:.4f} -> {ev['cv_rms_after_mm']:.4f} mm (t "
              f"{ev['cv_gain_t']:.1f}); {ev.get('description') or ev['physical']}")
        if ev.get("confusable_with"):
            print(f"      one class with {[c['label'] for c in ev['confusable_with']]}: {ev['experiment']}")
    print(f"  {diag['unexplained_structure']['text']}")
    for name, b in (("diagnose", diag["budget"]), ("reprocess", None if rep.budget is None else rep.budget.to_dict())):
        if b:
            print(f"  {name} budget on {b['n_points']} held-out points: " + "; ".join(
                f"{c['name']} {c['rms_mm']:.4f} [{c['low_mm']:.4f}-{c['high_mm']:.4f}]" for c in b["components"])
                + f"; nominal {b['nominal_rms_mm']:.4f} mm, sum {b['sum_rms_mm']:.4f} mm, closure "
                  f"{100 * b['closure']:.2f} %")
    print(f"  remainder: {diag['remainder']['kind']}: {diag['remainder']['text']}")
    print(f"  residual layer: {diag['layer'].get('text')}")
    for t in diag["layer"].get("terms", []):
        print(f"    term {t['term']}: {t['rms_before_mm']:.4f} -> {t['rms_after_mm']:.4f} mm (t {t['t']:.1f}, "
              f"{100 * t['share_of_layer']:.0f} % of the joint GP's gain)")
    for st in diag["next_steps"]:
        print(f"  next: {st['class']}: {st['experiment']} (predicted shrinkage {st['predicted_shrinkage_mm']:.4f} mm,"
              f" at stake {st['at_stake_mm']:.4f} mm)")
    same = [f["evidence"]["label"] for f in acc] == (sel["taken"] if sel else [])
    print(f"  same accepted effects in both commands: {same}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--no-self-check", action="store_true")
    ap.add_argument("--budget-only", action="store_true", help="only the budget forms (N seeds each)")
    ap.add_argument("--csv")
    ap.add_argument("--config")
    args = ap.parse_args()
    if args.csv:
        bench_csv(args.csv, args.config)
        return
    if args.budget_only:
        bench_budget_forms(args.seeds)
        return
    bench_time()
    bench_lag_backlash()
    if not args.no_self_check:
        bench_self_check(args.seeds)


if __name__ == "__main__":
    main()
