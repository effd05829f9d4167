"""Should the effect selection also take an effect on the ranks of its per-point gain? Held-out RMS of the default
process and the diagnosis self-check, with and without the rank rule (``robocal.effects.select.RANK_Z``).

Protocol (issue 32, seventh; written with the code of the rule, before it ran on any judged data set; this docstring
and that code are committed before the run; nothing about the method, the data or the rule changes after it without
being disclosed beside the figures):
  * What is judged: beside its two rules on the paired t (t > 3 and a held-out RMS gain > 2 %, or t > 2 and > 10 %),
    the effect selection also takes a candidate whose gain is > 10 % and whose one-sided Wilcoxon signed-rank z of
    the per-point squared-error differences is > 2 (the large-gain rule's level, read from the ranks). The same
    evidence keeps a part of an effect (pruning) and an effect in the final check. Everything else in the default
    process is unchanged, and ``campaign diagnose`` runs the same selection.
  * Why: on the sixth protocol's breakdown (sparse-far-pose form, seed 18, ``f-task`` at 100 rows, 13.5 x) the
    selection took no effect: joint compliance, the form's own effect, lowered the CV RMS by 36 % at t 1.92. A few far
    poses dominate the per-point differences, so a large gain spread over most poses gets a small t. On those rows
    57 % of the points improved, one-sided signed-rank p = 0.013 (z about 2.2). On two geometry-only truth controls
    (seeds 201 and 202, all rows and ``f``'s 50) no candidate reached p < 0.10 (z about 1.3). These are the only
    figures seen before this was fixed; no other data set ran with the rule.
  * (i) Issue 32's forms: the public UR5 campaign (not fresh) and the six simulated forms of
    ``select_forms.ADAPTIVE_FORMS`` at fresh seeds 19 20 21. Per data set: all rows, and the adaptive replay's rows
    under the campaign's rule ``f`` at 50 and 100 (chosen once, with the rule off; under ``f`` the picks do not
    depend on the model). Figure: held-out RMS with the rule over without, for each of the 3 x 19 sets. Also printed:
    issue 32's ratios against all rows (50 and 100) with and without, per form (mean over the seeds).
  * (ii) The breakdown above (known data): ``f-task`` at 80 and 100 rows, with and without.
  * (iii) The diagnosis self-check (``campaign diagnose --self-check``) at fresh trial seeds (first seed 5000, 5 per
    effect and form: 5 per effect, 10 controls, 10 pairs, 5 out-of-library, 5 per failure-class form), with and
    without: effects named right, controls clean, spurious acceptances, whether its targets pass.
  * Development before this was fixed: the self-check part ran once on its known seeds (first seed 1000, 1 per
    effect) to test the script: the same figures with and without; part (i) ran on development seed 101 of one form
    to test the script (figures below the outcome).
  * Choice: the rule is kept (RANK_Z = 2) if over (i) the mean ratio is at most 1.000, none exceeds 1.05 and none
    of the UR5's exceeds 1.01; and in (iii) with the rule no fewer single effects and forms are named right, no
    fewer controls are clean, and no more acceptances are spurious than without. Otherwise RANK_Z becomes None
    (no rank rule).

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_rank_take.py [--seeds 19 20 21]
        [--parts i ii iii] [--forms ...] [--json OUT.json] [--combine A.json B.json]

Outcome (run on 57a1e2c as two processes, ``--parts i ii --forms`` UR5 + compliance + gear + drift + sparse far +
layer only and ``--parts i iii --forms`` lag + UR10-like + IRB 4600-like, then ``--combine``): the rule is kept.
  * (i) 57 figures (the UR5's 3 and 54 at seeds 19-21), every ratio 1.000: the rule changed no choice there.
  * (ii) f-task 80: 0.0433 mm both; f-task 100: 0.5195 mm without, 0.0414 with (ratio 0.080; all rows 0.0385 mm at
    the task).
  * (iii) On 90 fresh data sets, without and with: named right 65/65, controls clean 10/10, 6 spurious
    acceptances, targets pass.
  * The script test before the protocol was fixed: read-back lag, seed 101, all rows / f 50 / f 100: 0.0350 /
    0.0390 / 0.0357 mm with and without.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import robocal.effects.select as select  # noqa: E402
from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from select_forms import ADAPTIVE_FORMS  # noqa: E402
from select_replay import rms_off_on  # noqa: E402
from switch_protocol import arguments, line, run, switch  # noqa: E402

SELF_CHECK_SEED = 5000


rank_off, _ = switch(select, "RANK_Z", None, select.RANK_Z)   # the default process without the rank rule


def part_ii(tmp: Path, parts) -> None:
    if "ii" not in parts:
        return
    from bench_select_task import task_data
    ds, cell, task_q = task_data(*ADAPTIVE_FORMS["strong compliance, sparse far"](tmp, 18))
    with rank_off():
        order = adaptive_rows(ds, cell, 100, task_q_rad=task_q, cover_task=True).order
    for n in (80, 100):
        line(f"(ii) sparse far seed 18, f-task {n} (at the task)", *rms_off_on(ds, cell, order[:n], rank_off))


def main() -> None:
    args = arguments(__doc__, (19, 20, 21), SELF_CHECK_SEED, ("i", "ii", "iii")).parse_args()
    run(args, rank_off, "rank rule", "iii", part_ii)


if __name__ == "__main__":
    main()
