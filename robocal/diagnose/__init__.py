"""Sim-to-real gap diagnosis: where the residual of the best geometric model lies, which unmodelled effect
causes it and how far it shrinks once that effect is added (effects.md §5-6, "RANCE").

Pure numerics: arrays in, dataclasses out. Steps (``diagnose``):

1. **Base fit**: registration + identifiability + Levenberg-Marquardt of the complete geometric model
   (``robocal.identify.calibrate``); gross outliers (> 5 robust sigma) are set aside.
2. **Candidates** (``build_candidates``): each library effect as groups of regressor columns, a joint-space
   basis ``dq`` (rad per unit parameter, mapped to the SMR by the joint Jacobian) and/or a tracker-frame basis
   ``dp`` (mm per unit parameter). Forms are deliberately more general than the simulator's: compliance from the
   gravity lever arms of every downstream joint point (any lumped-mass model on the link lines), cyclic errors
   with harmonics 1-4 chosen by the data, thermal growth per link length with a warm-up time constant scanned
   0.25-5 h (or the logged temperature), registration drift with a linear or settling profile.
   Metadata checks decide first whether an effect *can* show in these data (timestamps, approach changes,
   two payloads, joint range, SMR off the J6 axis); absorption by geometry is measured on the regressors.
3. **Scoring** on the calibration set, linearised at the current fit: every regressor is orthogonalised against
   the geometric Jacobian and the effects already accepted (so only the non-absorbed part counts); the groups of
   a candidate are chosen greedily by BIC; score = ΔBIC (n = 3 x points, RSS-based so it does not trust the
   noise model's scale), extra-sum-of-squares F test, blocked K-fold cross-validation (by pose; contiguous time
   blocks for time effects), and the physical plausibility of the fitted values.
4. **Forward selection, strongest evidence first**: accept the candidate with the lowest ΔBIC that passes the
   named gates (ΔBIC < -10, absorption, veto by a direct comparison, blocked CV, physical plausibility judged on
   physical parameters such as stiffness or lag, the saturation test backlash vs read-back lag, the nested test
   compliance vs payload deflection); refit geometry + accepted effects with the exact (nonlinear) forward model;
   repeat until no candidate passes. Then the survivors must pass again in the final model: an effect-agnostic
   reach-split consistency check, CV against the model without them, ΔBIC of removal; groups no longer needed are
   pruned. A better-scored candidate rejected by a gate whose visible subspace overlaps the winner's, and
   near-ties with overlapping subspaces, are reported as one confusable class with the separating experiment.
5. **Where**: held-out test residuals and cross-validated calibration residuals of the geometric model (and of
   the final model) mapped over workspace cells, each joint's range, base axes, time, approach direction and
   payload; regions whose RMS exceeds the noise floor significantly (chi-square, Bonferroni) are named.
6. **Unexplained**: a k-nearest-neighbour permutation test for residual structure left in the final model
   (joint space, workspace, time and each single input); significant structure above a third of the floor is
   reported as ``unexplained`` together with where it lies.

Joint numbers are 1-based everywhere in the output. Modules: ``records`` (options, input, result records),
``candidates`` (the effect library, nest drift), ``engine`` (Gauss-Newton fits, designs, CV), ``scoring`` and
``selection`` (forward/backward selection through the gates), ``regions`` (where-analysis, maps, structure left
over), ``prose`` and ``result`` (evidence, findings, the ``Diagnosis``), ``core`` (``diagnose``).
"""
from __future__ import annotations

from ..approach import approach_signs as approach_from_order
from ..effects import EFFECT_NAMES
from .candidates import (Candidate, Group, Profile, arm_mass_kg, build_candidates, direct_lag, gravity_levers,
                         nest_drift, payload_levers, physical_torque_nm, robot_reach_mm, stiffness_floor_nm_per_rad)
from .core import diagnose
from .prose import REMEDY, SEPARATING_EXPERIMENT, separating_experiment
from .records import (Diagnosis, DiagnosisInput, DiagnosisOptions, Finding, NestReadings, Region,
                      moves_from_order)
from .regions import structure_test, where_analysis

__all__ = ["Candidate", "Diagnosis", "DiagnosisInput", "DiagnosisOptions", "EFFECT_NAMES", "Finding", "Group",
           "NestReadings", "Profile", "REMEDY", "Region", "SEPARATING_EXPERIMENT", "approach_from_order",
           "arm_mass_kg", "build_candidates", "diagnose", "direct_lag", "gravity_levers", "moves_from_order",
           "nest_drift", "payload_levers", "physical_torque_nm", "robot_reach_mm", "separating_experiment",
           "stiffness_floor_nm_per_rad", "structure_test", "where_analysis"]
