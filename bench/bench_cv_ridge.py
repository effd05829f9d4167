"""Should the effect selection's cross-validated fits damp the directions that the fit after it fixes at zero?
Held-out RMS of the default process and the diagnosis self-check, with ``robocal.effects.cv.RIDGE`` at 1e-9 (main
before this change) and at 1e-6.

Protocol (issue 32, fifteenth; written with the code of the change, before it ran on any judged data set; this
docstring and that code are committed before the run; nothing about the method, the data or the choice changes
after it without being disclosed beside the figures):
  * What is judged: the blocked cross-validation of the effect selection (``robocal.effects.cv.BlockedCV``: every
    fold's fit, the scans' nested choices, the shares absorbed and the fits on all points) solves its normal
    equations on unit-norm columns with a ridge. At 1e-9 it gives weight to directions whose relative residual is as
    small as 3e-5. The fit that the selection chooses for (``robocal.effects.fit.calibrate_elastic``) fixes at zero
    every column whose relative residual is below ``CalibrationOptions.rank_tol`` = 1e-3. So the cross-validation
    judged a model that is never fitted: on few rows, near-redundant columns took large weights in the training folds
    and inflated the held-out errors of rich candidates. The change sets the ridge to rank_tol^2 = 1e-6, the soft
    form of the same threshold. The value follows from rank_tol; no other value was tried.
  * Why: at fresh seeds 43-51 (``bench_goals.py``) one goal is missed: compliance + gear + drift at 50 poses, mean
    1.526. Development look (scratch scripts, seed 43, already used; before this was fixed): at rule ``f``'s 50 rows
    the selection took the lever form of compliance and a time drift, 0.0748 mm against 0.0323 at all rows (which
    take the link form, the drift and a J3 cyclic error). Configured on the same 50 rows: the link form + drift
    0.0398, the all-rows set 0.0363, the lever form + drift + J3 0.0775. The link form also generalised from 40 of
    those rows (0.0429) and from 50 random rows (0.0435). Yet the cross-validation scored it worse than the lever
    form (held-out 0.0635 against 0.0535 mm), and scored the lever form at 0.0457 while its in-sample RMS was 0.0556.
    With the ridge at 1e-6 the same 50 rows take the link form and the drift: 0.0398 mm (ratio 2.32 -> 1.23); 100
    rows and all rows unchanged (0.0344, 0.0323).
  * (i) Issue 32's forms: the public UR5 campaign (not fresh) and the six simulated forms of
    ``select_forms.ADAPTIVE_FORMS`` at fresh seeds 52 53 54. Per data set: all rows, and the adaptive replay's rows
    under the campaign's rule ``f`` at 50 and 100 (chosen once, with the change off; under ``f`` the picks do not
    depend on the model). Figure: held-out RMS with the change over without, for each of the 3 x 19 sets. Also
    printed: issue 32's ratios against all rows.
  * (ii) The diagnosis self-check (``campaign diagnose --self-check``) at fresh trial seeds (first seed 12000, 5 per
    effect and form), with and without: effects named right, controls clean, spurious acceptances, whether its
    targets pass.
  * Choice (the seventh's rule): the change is kept (``RIDGE = 1e-6``) if over (i) the mean ratio is at most 1.000,
    none exceeds 1.05 and none of the UR5's exceeds 1.01; and in (ii) with it no fewer single effects and forms are
    named right, no fewer controls are clean, and no more acceptances are spurious than without. Otherwise it goes
    back to 1e-9.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_cv_ridge.py [--seeds 52 53 54]
        [--parts i ii] [--forms ...] [--json OUT.json] [--combine A.json B.json]

Outcome (run on f3999cb as two processes, ``--parts i --forms`` UR5 + compliance + gear + drift + sparse far + layer
only and ``--parts i ii --forms`` lag + UR10-like + IRB 4600-like, then ``--combine``): **kept**.
  * (i) 57 figures: mean ratio 0.9888, largest 1.000, smallest 0.682. Only the compliance + gear + drift form moved:
    seed 53 f 50 0.0602 -> 0.0411 mm and f 100 0.0526 -> 0.0388, seed 54 all rows 0.0365 -> 0.0344. The 54 other
    figures, the UR5's three among them, are 1.000.
  * (ii) On 90 fresh data sets, without and with: named right 64/65, controls clean 10/10, 9 spurious acceptances;
    the self-check's targets are missed both ways (one trial of five of a single cyclic error, seed 12013: a J2
    error whose geometric model was already 1.15 x the floor, nothing accepted).
  * Issue 32's ratios at these seeds, off -> on (mean over seeds, worst): compliance + gear + drift 1.457 (1.723) ->
    1.297 (1.557) at 50 poses, 1.189 (1.506) -> 1.077 (1.110) at 100; the other forms unchanged.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import robocal.effects.cv as cv  # noqa: E402
from switch_protocol import arguments, run, switch  # noqa: E402

SELF_CHECK_SEED = 12000

ridge_off, ridge_on = switch(cv, "RIDGE", 1e-9, 1e-6)


def main() -> None:
    args = arguments(__doc__, (52, 53, 54), SELF_CHECK_SEED, ("i", "ii")).parse_args()
    run(args, ridge_off, "the cross-validation's ridge at rank_tol^2", "ii", on=ridge_on)


if __name__ == "__main__":
    main()
