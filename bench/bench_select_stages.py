"""Where an adaptive selection loses against the one-shot one (issue 32, after the revised protocol's run; it chose
nothing): the held-out RMS by stage of the default process on the chosen rows, and the effect selection's trial of
joint compliance.

* The public UR5 campaign: kinematic / + effects / final (with the residual layer) for the adaptive replay (the
  campaign's seed, rule ``d``: the rule of that run) and the one-shot ``campaign select`` at 50 and 100 rows, and
  for all rows.
* Seed 4 of the sparse-far-pose form of ``bench_select.py --adaptive``: the D-optimal and the space-filling seed's
  replays (rule ``d``) at 50 rows, the held-out RMS, and the compliance trial's CV RMS, gain and paired t.
* Seed 8 of the UR10-like form (the third protocol's run, where rule ``d`` broke down at 50 rows): rules ``d`` and
  ``f`` at 50 rows, by stage, with the effects taken.
* Seeds 7 and 9 of the sparse-far-pose form (where rule ``f`` misses the goal at 50 rows): all rows and ``f``'s 50,
  by stage, with the layer chosen.
* Where the task-covering picks of ``bench_select_task.py`` broke down, at the task (``--only task``: this section
  alone): seed 10 of the IRB 4600-like form (fourth protocol), ``f`` and ``f-task`` at 50 and 60 rows, by stage, with
  the effects taken, without the clock-place check of ``bench_drift_place.py`` (the code of that run) and at 50 rows
  with it; seed 18 of the sparse-far-pose form (sixth protocol), ``f-task`` at 80 and 100 rows with the first trial
  of joint compliance.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_select_stages.py [--only task]
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from campaign.calibrate.selection import select_rows  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from select_forms import ADAPTIVE_FORMS, ur5_dataset  # noqa: E402


def report(ds, cell, rows=None):
    """The default process's report on the calibration rows ``rows`` (all when None) and every other row."""
    if rows is not None:
        keep = ~ds.mask("calib")
        keep[np.asarray(rows, int)] = True
        ds = ds.with_order_context().subset(keep)
    return calibrate_dataset(ds, cell).report


def stages(r) -> str:
    return " / ".join(f"{v.test.rms_mm:.4f}" for v in r.stages.values() if v is not None) + \
        f"  ({', '.join(r.effects.selection['taken']) or 'no effect'}; layer {r.method.residual})"


def task_breakdown(tmp: Path) -> None:
    """The two breakdowns of the task-covering picks (``bench_select_task.py``), at the task, by stage: IRB 4600-like
    seed 10 (fourth protocol) without and with the clock-place check of ``bench_drift_place.py``, and sparse-far
    seed 18 (sixth protocol) with the trial of joint compliance."""
    from bench_drift_place import check_off
    from bench_select_task import task_data
    ds, cell, task_q = task_data(*ADAPTIVE_FORMS["IRB 4600-like (compliance + J3 gear + coupling)"](tmp, 10))
    with check_off():
        print(f"IRB 4600-like, seed 10, at the task: held-out RMS by stage, mm (all rows: {stages(report(ds, cell))})")
        sel = {cover: adaptive_rows(ds, cell, 60, task_q_rad=task_q, cover_task=cover) for cover in (False, True)}
    for cover in (False, True):
        for n in (50, 60):
            with check_off():
                off = stages(report(ds, cell, sel[cover].order[:n]))
            print(f"  {'f-task' if cover else 'f':6s} {n}, no clock-place check: {off}")
        print(f"  {'f-task' if cover else 'f':6s} 50, the check: {stages(report(ds, cell, sel[cover].order[:50]))}")
    ds, cell, task_q = task_data(*ADAPTIVE_FORMS["strong compliance, sparse far"](tmp, 18))
    print(f"strong compliance, sparse far, seed 18, at the task (all rows: {stages(report(ds, cell))})")
    sel = adaptive_rows(ds, cell, 100, task_q_rad=task_q, cover_task=True)
    for n in (80, 100):
        r = report(ds, cell, sel.order[:n])
        trial = next(t for t in r.effects.selection["trials"] if t["effect"].startswith("joint_compliance"))
        print(f"  f-task {n}: {stages(r)}; round-1 {trial['effect']}: CV {trial['base_cv_rms_mm']:.4f} -> "
              f"{trial['cv_rms_mm']:.4f} mm (gain {100 * trial['gain']:.0f} %, t {trial['t']:.2f})")


def main() -> None:
    if sys.argv[1:] == ["--only", "task"]:
        with tempfile.TemporaryDirectory() as tmp:
            task_breakdown(Path(tmp))
        return
    ds, cell = ur5_dataset()
    print("UR5 public campaign: held-out RMS by stage, mm (nominal / kinematic / + effects / final)")
    print(f"  all {int(ds.mask('calib').sum())} rows: {stages(report(ds, cell))}")
    sel = adaptive_rows(ds, cell, 100, rule="d")
    for n in (50, 100):
        print(f"  adaptive {n}: {stages(report(ds, cell, sel.order[:n]))}")
        one = np.flatnonzero(select_rows(ds, cell, n).keep & ds.mask("calib"))
        print(f"  one-shot {n}: {stages(report(ds, cell, one))}")
    with tempfile.TemporaryDirectory() as tmp:
        ds, cell = ADAPTIVE_FORMS["strong compliance, sparse far"](Path(tmp), 4)
        print("strong compliance, sparse far poses, seed 4, 50 rows: held-out RMS and the compliance trial")
        for design in ("d_optimal", "space_filling"):
            r = report(ds, cell, adaptive_rows(ds, cell, 50, rule="d", seed_design=design).order[:50])
            trial = next(t for t in r.effects.selection["trials"] if t["effect"].startswith("joint_compliance"))
            print(f"  {design:14s} held-out {r.final.test.rms_mm:.4f} mm; {trial['effect']}: CV "
                  f"{trial['base_cv_rms_mm']:.3f} -> {trial['cv_rms_mm']:.3f} mm (gain {100 * trial['gain']:.0f} %, "
                  f"t {trial['t']:.2f}), taken: {', '.join(r.effects.selection['taken']) or 'none'}")
        ds, cell = ADAPTIVE_FORMS["UR10-like (compliance + J2 gear)"](Path(tmp), 8)
        print(f"UR10-like, seed 8, 50 rows: held-out RMS by stage, mm (all rows: {stages(report(ds, cell))})")
        for rule in ("d", "f"):
            print(f"  rule {rule}: {stages(report(ds, cell, adaptive_rows(ds, cell, 50, rule=rule).order[:50]))}")
        for seed in (7, 9):
            ds, cell = ADAPTIVE_FORMS["strong compliance, sparse far"](Path(tmp), seed)
            print(f"strong compliance, sparse far poses, seed {seed}: held-out RMS by stage, mm")
            print(f"  all {int(ds.mask('calib').sum())} rows: {stages(report(ds, cell))}")
            print(f"  rule f, 50 rows: {stages(report(ds, cell, adaptive_rows(ds, cell, 50, rule='f').order[:50]))}")
        task_breakdown(Path(tmp))


if __name__ == "__main__":
    main()
