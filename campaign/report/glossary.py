"""The terms the reports print, defined once: the HTML report's glossary section (``docs/report.md`` repeats it
for readers of the terminal output)."""
from __future__ import annotations

from campaign.io.quantities import CONDITION_SCALE

UNCORRECTED = ("the test points commanded at their planned joints, measured against the targets through the "
               "calibrated model's registration; usually larger than the calibration report's nominal stage on the "
               "same points, because that stage fits its own registration to the nominal model, which absorbs the "
               "part of the error a rigid frame can take up")
"""``verify``'s "uncorrected" against the calibration's "nominal", in one sentence (terminal, HTML, glossary)."""
UNCORRECTED_VS_NOMINAL = f"uncorrected = {UNCORRECTED}"

_good, _fair = (f"{bound:,.0f}" for bound, _ in CONDITION_SCALE[:2])

GLOSSARY = (
    ("calibration set / test set",
     "The calibration points are the ones the model is fitted to; the test points are held out (never used by the "
     "fit) and judge its accuracy. A figure on the calibration set is a fit to its own points, not an accuracy; "
     "every figure is labelled with its set."),
    ("held-out",
     "Measured on points the model never saw: the test set, or the left-out fold of a cross-validation."),
    ("nominal",
     "The controller's nominal kinematic model, with the tracker-to-base registration and the SMR offset fitted to "
     "the calibration points. Its RMS on the calibration set (plausibility line) and on the test set (the "
     "position-error table) are two numbers of the same model on different points."),
    ("uncorrected (verify)", UNCORRECTED[0].upper() + UNCORRECTED[1:] + "."),
    ("noise floor",
     "The RMS position error a perfect model would still show: tracker noise plus the robot's repeatability, from "
     "repeated poses when the data have them, else from the specifications. Printed with one format everywhere."),
    ("RMS / floor",
     "The held-out RMS as a multiple of the noise floor: about 1 means the model explains everything above the "
     "noise; well above 1, something is unmodelled."),
    ("CV RMS, t", "The RMS of cross-validation held-out errors on the calibration points, and the paired t "
     "statistic of the per-point squared errors of two models (the rule that takes an effect is stated in the "
     "physical-effects section)."),
    ("condition number",
     "Ratio of the largest to the smallest singular value of the column-scaled identification Jacobian: how much "
     f"measurement noise can be amplified in the identified parameters. Up to {_good} good; up to {_fair} fair "
     f"(some combinations weakly determined: see the parameter sigmas); above {_fair} poor: some combinations are "
     "barely determined by this pose set. The held-out figures remain the test of accuracy."),
    ("aliased with", "A parameter whose effect on the measured points another parameter (or combination) also "
     "produces: it cannot be told apart, so it stays at nominal and the other takes its share."),
    ("Hayati beta", "A rotation about the y axis added to a joint whose axis is parallel to the previous one, "
     "where the D-H parameters are ill-conditioned."),
    ("physical effects", "Joint compliance, gear cyclic error, backlash, read-back lag, drift...: terms added to "
     "the geometric model when cross-validation shows they predict held-out points better."),
    ("residual layer", "A non-parametric correction (IDW or GPR) fitted to what the model leaves; kept only when "
     "cross-validation shows it predicts held-out points."),
    ("SIMULATED", "A mock:// robot or tracker took part: the measurements come from the simulated cell of the "
     "config's simulation section, and the cell's times (measuring time, ETA) are simulated time."),
    ("ISO 9283 cube, P1..P5, cycle", "The ISO 9283 pose test: P1 is the centre of the largest cube in the plan's "
     "box, P2..P5 lie on the diagonals of one of its diagonal planes at 0.1 L from the corners (L: the diagonal's "
     "length); the robot visits P1, P5, P4, P3, P2 in each of n cycles, so each pose is approached from the same "
     "neighbour. Nominal targets are the poses commanded through the nominal model, corrected ones through the "
     "calibrated model."),
    ("AP, APx, APy, APz", "Pose accuracy of a pose (mm): APx, APy, APz are the barycentre of the n attained "
     "positions minus the commanded position, per base-frame axis; AP = \u221a(APx\u00b2 + APy\u00b2 + APz\u00b2)."),
    ("RP, l\u0304, S_l", "Pose repeatability of a pose (mm): RP = l\u0304 + 3 S_l, where l_i is the distance of "
     "attained position i from the barycentre, l\u0304 the mean of the l_i and S_l their standard deviation (n - 1 "
     "in the denominator). The measured RP includes the tracker's own scatter."),
    ("RP tracker, RP robot", "The tracker's contribution to the measured RP: the RP of an isotropic scatter with "
     "the mean squared spread of the tracker's noise at the pose (from the config's tracker.uncertainty). The "
     "robot's RP is the measured RP with it removed "
     "in quadrature, \u221a(RP\u00b2 \u2212 RP_tracker\u00b2), with a 95 % interval from the measured RP "
     "\u2213 2 u (u: its "
     "jackknife standard uncertainty over the cycles). The ISO verdict compares the robot's RP with the "
     "datasheet's (robot.repeatability_mm): PASS when every pose's interval is at or below it, FAIL when one lies "
     "wholly above it, UNDECIDED otherwise."),
    ("AD", "Distance accuracy between two poses (P2 and P4, mm): the mean attained distance over the cycles minus "
     "the commanded distance (per axis too: ADx, ADy, ADz)."),
    ("RD", "Distance repeatability between the same two poses (mm): RD = \u00b13 S_D, S_D being the standard deviation "
     "of the attained distances over the cycles; stated as \u00b1RD."),
)
"""(term, definition) pairs, in reading order."""
