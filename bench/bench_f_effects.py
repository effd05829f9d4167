"""Should the effect selection take and keep whole effects on in-sample evidence too, its parts pruned as before?
Held-out RMS of the default process and the diagnosis self-check, with and without ``robocal.effects.select.F_LEVEL``
(``F_PARTS`` False).

Protocol (issue 32, eighteenth; written with the code of the change, before it ran on any judged data set; this
docstring and that code are committed before the run; nothing about the method, the data or the choice changes
after it without being disclosed beside the figures):
  * What is judged: the seventeenth protocol's rule (``bench/bench_f_evidence.py``) with one difference. An effect
    is taken when the held-out evidence takes it, or on in-sample evidence: a nested F-test on all rows of the
    whitened, linearised design (``BlockedCV.nested_p``) with p below 0.01 / the number of candidates, together
    with a held-out gain > 2 % that is positive under every blocking (not a scan's pick). The final check keeps an
    effect on the same in-sample evidence. The parts of a taken effect (a joint, a harmonic) are pruned on held-out
    evidence alone, as without the change (``F_PARTS = False``).
  * Why: the seventeenth protocol (F_PARTS True) was not kept. Over its 111 figures the mean ratio was 0.9930 and 14
    of the 15 that moved were better (the compliance + gear + drift form at 50 poses 1.528 -> 1.451 over seeds
    73-78), but one exceeded 1.05: IRB 4600-like seed 78 at 50 rows, 0.0450 -> 0.0475 mm. A look after that
    verdict (a scratch script, on that seed): both harmonics of the truth's J3 error were taken, and the pruning
    then kept h2 on the in-sample evidence (p 8.29e-4 against a level of 8.3e-4; held-out t 1.62) and pruned h1
    (p 2.6e-3, t 1.75), where the held-out rule alone keeps h1. Which part of an effect predicts is the held-out
    rule's question; the in-sample test only adds power to whether an effect is there. Scratch looks with this form
    (F_PARTS False): on the used seeds 43-66 of the compliance + gear + drift form at 50 rows it gives the figures of
    F_PARTS True on every seed (1.341 -> 1.298 over the 24); on IRB 4600-like seed 78 at 50 rows 0.0450 mm, as
    without the change. Nothing else was looked at.
  * (i) Issue 32's forms: the public UR5 campaign (not fresh) and the six simulated forms of
    ``select_forms.ADAPTIVE_FORMS`` at fresh seeds 79-84. Per data set: all rows, and the adaptive replay's rows
    under the campaign's rule ``f`` at 50 and 100 (chosen once, with the change off; under ``f`` the picks do not
    depend on the model). Figure: held-out RMS with the change over without, for each of the 3 x 37 sets. Also
    printed: issue 32's ratios against all rows.
  * (ii) The diagnosis self-check (``campaign diagnose --self-check``) at fresh trial seeds (first seed 15000, 5 per
    effect and form), with and without: effects named right, controls clean, spurious acceptances, whether its
    targets pass.
  * Choice (the seventh's rule): the change is kept (``F_LEVEL = 0.01``, ``F_PARTS = False``) if over (i) the mean
    ratio is at most 1.000, none exceeds 1.05 and none of the UR5's exceeds 1.01; and in (ii) with it no fewer
    single effects and forms are named right, no fewer controls are clean, and no more acceptances are spurious
    than without. Otherwise ``F_LEVEL`` goes back to None.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_f_effects.py [--seeds 79 ... 84]
        [--parts i ii] [--forms ...] [--json OUT.json] [--combine A.json B.json]

Outcome (run on b4b594f as two processes, ``--parts i --forms`` UR5 + compliance + gear + drift + sparse far + layer
only and ``--parts i ii --forms`` lag + UR10-like + IRB 4600-like, then ``--combine``): **not kept**; ``F_LEVEL``
stays None.
  * (i) 111 figures: mean ratio 0.9893, largest **1.063** (the rule asks that none exceed 1.05), smallest 0.734.
    15 moved, 13 of them better: compliance + gear + drift seeds 80, 81 and 82 at 50 rows 0.0541 -> 0.0438,
    0.0454 -> 0.0390 and 0.0707 -> 0.0527 mm, seed 81 at 100 0.0456 -> 0.0335; layer only seed 80 at 50 0.0509 ->
    0.0421; and eight smaller. Two worse: IRB 4600-like seed 81 at 50 rows 0.0485 -> 0.0516, UR10-like seed 83 at
    100 0.0509 -> 0.0510. The UR5's three figures did not move.
  * (ii) On 90 fresh data sets, without and with: named right 65/65 both, controls clean 10/10 both, spurious
    acceptances 10 both; the self-check's targets pass both ways.
  * Issue 32's ratios at these seeds, off (the code as it stays) -> on, 50 poses; 100 poses: compliance + gear +
    drift 1.476 (worst 1.953) -> 1.312 (1.505); 1.131 (1.433) -> 1.054 (1.079); strong compliance, sparse far 1.145
    (1.270); 1.032 (1.070), unchanged; layer only 1.224 (1.464) -> 1.182 (1.307); 1.066 (1.096); read-back lag
    1.073 (1.113); 1.022 (1.053), unchanged; UR10-like 1.029 (1.045) -> 1.025 (1.037); 1.017 (1.021) -> 1.014
    (1.021); IRB 4600-like 1.104 (1.158) -> 1.110 (1.158); 1.045 (1.061) -> 1.031 (1.050); UR5 1.218; 1.073.
  * Why seed 81 of the IRB 4600-like form lost (a look after the verdict, a scratch script): on the in-sample
    evidence the selection took the axis coupling the truth has (held-out gain 6.7 %, t 1.26, p 8.7e-5 against a
    level of 8.3e-4); given it, the held-out rule then took a J1 cyclic error of order 18 from the scan (gain 8.9 %,
    t 3.09) that the truth does not have. Without the change it took neither.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import robocal.effects.select as select  # noqa: E402
from switch_protocol import arguments, run, switch_many  # noqa: E402

SELF_CHECK_SEED = 15000

f_off, f_on = switch_many(select, {"F_LEVEL": None, "F_PARTS": False}, {"F_LEVEL": 0.01, "F_PARTS": False})


def main() -> None:
    args = arguments(__doc__, (79, 80, 81, 82, 83, 84), SELF_CHECK_SEED, ("i", "ii")).parse_args()
    run(args, f_off, "whole effects taken on in-sample evidence too", "ii", on=f_on)


if __name__ == "__main__":
    main()
