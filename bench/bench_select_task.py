"""Issue 32, fourth protocol: should a task steer the rounds' picks? Held-out RMS at the task, adaptive replay with
``plan.task``, rule ``f`` with and without covering the task, against all rows.

Protocol (written, with the code of the task-covering picks, before they ran on any data set; this docstring and
that code are committed before the run; nothing about the method, the forms, the task or the seeds changes after it
without being disclosed beside the figures):
  * What is judged: ``campaign.plan.adaptive.COVER_TASK``. Today (False) rule ``f`` picks, each round, the candidates
    farthest in lever-scaled joint space from every pose measured or picked, whatever ``plan.task`` says; the task
    only weighs the predicted held-out RMS, and so the stop. The candidate (True): each pick the free candidate
    nearest the task pose farthest from every pose measured or picked (``robocal.design.adaptive.Coverage`` with
    task poses), so the poses after the seed sit where the robot will work. The seed (space-filling over every
    candidate), batches of 10, the refit and the default process are unchanged. Without a task nothing changes.
  * Why: issue 32 asks that a task steer the selection ("the few poses must sit where the work is"); the third
    protocol's rule ``f`` ignores it.
  * Forms (seven): the public real UR5 campaign split as ``bench_select.py --forms ur5-split`` does (its grid in
    seeded halves: 500 calibration rows, held out the other half and the 20 random poses), and the six simulated
    forms of ``bench_select.py --adaptive`` (``select_forms.ADAPTIVE_FORMS``). Seeds 10 11 12, fresh for the
    simulated forms (never run before this paragraph was committed); the UR5 campaign is not fresh data, its
    halves of seeds 10-12 are new.
  * The task of a data set: the box, in the robot base frame, from the 20th to the 80th percentile of the held-out
    poses' SMR positions on each axis (nominal model: what a plan knows); 10th to 90th when that box holds fewer
    than 10 held-out poses. The selection is given the calibration rows whose SMR lies in the box (what
    ``plan.task.box_mm`` gives); the held-out figure is over the held-out poses in the box only (the others are
    dropped from the data set every method is judged on).
  * Methods at 50 and 100 calibration poses: ``f`` (today: the replay with the task, picks ignoring it) and
    ``f-task`` (the picks cover the task); the 50-pose selection is the first 50 rows of the replay to 100.
  * Score: held-out RMS at the task of the default process on the chosen rows over that of all calibration rows of
    the same data set; per form the mean over its seeds; overall the mean over the seven forms of the mean of the
    two sizes (the UR5 one form among seven).
  * Choice: ``COVER_TASK`` becomes True only if ``f-task``'s overall score is more than 1 % lower than ``f``'s.
  * Development before this was fixed: the covering pick was unit-tested on synthetic points, and this script ran
    once on development seed 101 of the read-back-lag form (f 1.176 / 1.053, f-task 1.076 / 1.051 at 50 / 100; the
    box held 42 candidates). That run showed a fault of the mechanics, fixed before the run: once every task pose
    was measured, the picks clustered at the first task pose (every distance 0); they now go back to farthest-first
    over every candidate. Nothing else changed after it.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select_task.py [--seeds 10 11 12]
        [--forms ...] [--json OUT.json] [--combine A.json B.json]

Outcome (run on 811e0f1 in two processes, then --combine; the table is in docs/results.md): score f-task 1.213, f
1.202, so the task-covering picks are not taken. f-task is lower at 50 poses on six forms of seven, and at 100 on four,
the UR5 at both (1.384 / 1.122 against 1.557 / 1.228). One data set decided it: on seed 10 of the IRB 4600-like
form, f-task's 50 rows took a spurious registration drift in measurement order (3.18 x;
``bench_select_stages.py --only task``). After the run, ``task_data`` was split out of ``evaluate`` for that
script (one data set re-run gave the same figures), and the switch ``COVER_TASK`` was removed: the campaign never
sets it, and the candidate stays here as ``adaptive_rows(..., cover_task=True)``.
After the sixth run, ``ur5_split`` reuses ``bench_select.ur5_split_datasets`` (the same halves: UR5 seed 10 re-run
gives the fourth run's figures).

Sixth protocol: the same comparison on fresh seeds, after the fifth (written after the fifth protocol's outcome and
before this run; committed on its own before it). Everything above holds except what is named here.
  * Why again: the fourth run was decided by one breakdown, a spurious registration drift in measurement order.
    The fifth protocol (``bench_drift_place.py``) judged a fix for that failure, and the fix is now in the default
    process. The candidate is unchanged.
  * Seeds: 16 17 18, fresh for the simulated forms; the UR5 halves of seeds 16-18 are new, the campaign is known.
  * Choice: the same rule. The task-covering picks are taken only if their score on seeds 16-18 is more than 1 % lower
    than ``f``'s. Seeds 10-12 are not re-run: they were seen.
  * If taken, the switch returns in ``campaign.plan.adaptive``, and the rounds, the plan's forecast order and
    ``campaign select --adaptive`` use it when a config has ``plan.task``.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select_task.py --seeds 16 17 18
        [--forms ... --json A.json] [--combine A.json B.json]

Outcome of the sixth protocol (run on 331f79b in two processes, then --combine; the table is in docs/results.md):
score f-task 1.435, f 1.179, so the task-covering picks are not taken, for the second time. They were lower on the
mean at 50 poses (1.199 against 1.255). On seed 18 of the sparse-far-pose form at 100 poses they broke down: 13.5 x.
On those rows the effect selection took no effect. Joint compliance lowered the CV RMS by 36 %, but its paired t was
1.92, below the rule's 2: the gain was concentrated on a few far poses.

Eighth protocol: the same comparison on fresh seeds, after the seventh (written after the seventh protocol's outcome
and before this run; committed on its own before it). Everything of the sixth holds except what is named here.
  * Why again: the sixth run was decided by one breakdown, an effect selection whose paired t missed a large gain.
    The seventh protocol (``bench_rank_take.py``) judged a fix for that failure (the rank rule), and it is now in the
    default process; on the sixth run's breakdown it gives 0.0414 mm against 0.5195 (all rows 0.0385). The candidate
    is unchanged.
  * This is the third and last judgment of this candidate: whatever the outcome, it is not run again on other seeds.
  * Seeds: 22 23 24, fresh for the simulated forms; the UR5 halves of seeds 22-24 are new, the campaign is known.
  * Choice: the same rule. The task-covering picks are taken only if their score on seeds 22-24 is more than 1 % lower
    than ``f``'s. If taken, the switch returns in ``campaign.plan.adaptive`` and the rounds, the plan's forecast order
    and ``campaign select --adaptive`` use it when a config has ``plan.task``.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select_task.py --seeds 22 23 24
        [--forms ... --json A.json] [--combine A.json B.json]

Outcome of the eighth protocol (run on 09f80ba in two processes, then --combine; the table is in docs/results.md):
score f-task 1.142, f 1.164, so the task-covering picks are taken: ``campaign.plan.adaptive.COVER_TASK`` (True) and
``covered_task`` steer the rounds, the forecast's order and ``campaign select --adaptive`` when a config has
``plan.task``. Mean over forms at 50 poses 1.189 against 1.191, at 100 1.095 against 1.136; no breakdown (the largest
figure, 2.366, was f's on seed 23 of the compliance + gear + drift form at 50 poses; f-task 1.917 there).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from robocal.kinematics.models import smr_base  # noqa: E402
from bench_select import ur5_split_datasets  # noqa: E402
from select_forms import ADAPTIVE_FORMS  # noqa: E402
from select_replay import held_out_rms, subset_rms  # noqa: E402

SIZES = (50, 100)
METHODS = {"f": False, "f-task": True}
UR5_SPLIT = "UR5 real campaign, split halves"


def ur5_split(seed: int):
    """The UR5 campaign with one seeded half of its grid held out (``bench_select.ur5_split_datasets``)."""
    _, ds, cell, _ = next(ur5_split_datasets([seed]))
    return ds, cell


def task_box(p_test: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (3,) mm: the 20th-80th percentile box of the held-out SMRs, 10th-90th if it holds fewer than 10."""
    for q in (20, 10):
        lo, hi = np.percentile(p_test, q, axis=0), np.percentile(p_test, 100 - q, axis=0)
        if np.all((p_test >= lo) & (p_test <= hi), axis=1).sum() >= 10:
            break
    return lo, hi


def task_data(ds, cell):
    """(data set without the held-out poses outside the task, cell, the task's calibration poses (T, n) rad)."""
    q = np.radians(ds.q_deg)
    p = smr_base(cell.kinematics, np.where(np.isfinite(q), q, 0.0))
    test = ds.mask("test")
    lo, hi = task_box(p[test])
    inside = np.all((p >= lo) & (p <= hi), axis=1)
    ds = ds.with_order_context().subset(~test | inside)  # the held-out poses outside the task are not judged
    return ds, cell, q[~test | inside][ds.mask("calib") & inside[~test | inside]]


def evaluate(ds, cell) -> dict:
    """Ratios to all rows at the task per method and size, with the task's sizes."""
    ds, cell, task_q = task_data(ds, cell)
    q = np.radians(ds.q_deg)
    inside = np.any(np.all(np.isclose(q[:, None], task_q[None]), axis=2), axis=1) | ds.mask("test")
    everything = held_out_rms(ds, cell)
    out = {"all_mm": everything, "task_test": int(ds.mask("test").sum()), "task_cal": len(task_q)}
    for m, cover in METHODS.items():
        sel = adaptive_rows(ds, cell, max(SIZES), task_q_rad=task_q, cover_task=cover)
        for n in SIZES:
            out[f"{m}@{n}"] = subset_rms(ds, cell, sel.order[:n]) / everything
        out[f"{m}:in_task@100"] = int(np.sum(inside[sel.order[:100]]))
    return out


def summary(table: dict[str, list[dict]]) -> None:
    print(f"\n{'form':48s}" + "".join(f"{m + '@' + str(n):>12s}" for n in SIZES for m in METHODS))
    means = {}
    for form, rows in table.items():
        means[form] = {c: float(np.mean([r[c] for r in rows])) for c in rows[0] if "@" in c and ":" not in c}
        print(f"{form:48s}" + "".join(f"{means[form][f'{m}@{n}']:12.3f}" for n in SIZES for m in METHODS))
    score = {m: float(np.mean([np.mean([means[f][f"{m}@{n}"] for n in SIZES]) for f in means])) for m in METHODS}
    print(f"{'mean over forms':48s}" + "".join(f"{np.mean([means[f][f'{m}@{n}'] for f in means]):12.3f}"
                                             for n in SIZES for m in METHODS))
    print("score (mean over forms of the two sizes' mean): " + ", ".join(f"{m} {s:.3f}" for m, s in score.items()))
    take = score["f-task"] < 0.99 * score["f"]
    print(f"f-task taken: {take} (f-task {'more' if take else 'not more'} than 1 % below f)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[10, 11, 12])
    ap.add_argument("--forms", nargs="+", default=[UR5_SPLIT, *ADAPTIVE_FORMS])
    ap.add_argument("--json", type=Path)
    ap.add_argument("--combine", type=Path, nargs="+")
    args = ap.parse_args()
    if args.combine:
        table = {}
        for path in args.combine:
            for form, rows in json.loads(path.read_text()).items():
                table.setdefault(form, []).extend(rows)
        summary(table)
        return
    table = {}
    with tempfile.TemporaryDirectory() as tmp:
        for form in args.forms:
            for seed in args.seeds:
                ds, cell = ur5_split(seed) if form == UR5_SPLIT else ADAPTIVE_FORMS[form](Path(tmp), seed)
                r = evaluate(ds, cell)
                table.setdefault(form, []).append(r)
                print(f"{form:48s}{seed:4d}  all {r['all_mm']:.4f} mm, task: {r['task_test']} held out, "
                      f"{r['task_cal']} candidates; " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else
                                                                 f"{k} {v}" for k, v in r.items()
                                                                 if "@" in k), flush=True)
                if args.json:
                    args.json.write_text(json.dumps(table, indent=1))
    summary(table)


if __name__ == "__main__":
    main()
