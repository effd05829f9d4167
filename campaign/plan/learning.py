"""How many poses a plan needs, before anything moves: the forecast learning curve.

``forecast_curve``: the held-out RMS expected of the model fitted on the first n calibration poses, for n up to the
plan's count (``robocal.design.adaptive.learning_curve``): the noise floor at the test poses (tracker model + robot
repeatability) and the parameter uncertainty of the geometry and the pose-dependent effects ``calibration.effects:
auto`` may take, each with its prior (1 mm / 1 mrad, the effects' typical sizes), so that a parameter the first
poses cannot determine still counts with its prior. The poses in the order the plan measures them: an optimal plan's
order (its D-optimal greedy order); for an adaptive plan its seed, then the order its rounds take under rule ``f``
(farthest-first over the candidates, or covering ``plan.task``'s poses when it has one; a round judges a seeded
sample of at most 3000 of them, so a large pool's run differs in detail), or the D-optimal order of the candidates
under a rule whose choice depends on the measurements (the measured curve is in the run's report); for a grid plan
the D-optimal order of its calibration points (any prefix of a grid's serpentine would be one corner of the box).
What the model cannot express (the residual layer's work) is not in the forecast.
"""
from __future__ import annotations

import numpy as np

from robocal.design import (Coverage, choose_batch, criterion, criterion_effects, d_optimal, design_columns,
                            greedy_order, learning_curve, lever_scaled)

from campaign.config.cell_model import CellModel
from .adaptive import RULE, covered_task, task_poses
from .optimal import pose_covariance, tracker_kinematics
from .points import Plan

SIZES = (10, 25, 50, 75, 100, 150, 200, 300, 400, 500, 750, 1000)


def plan_order(cell: CellModel, plan: Plan) -> np.ndarray:
    """Calibration poses (N, n) rad in the order the forecast takes them (see the module docstring)."""
    q_cal = np.radians([p.q_deg for p in plan.points if p.set == "calib"]).reshape(-1, cell.kinematics.n)
    kind = cell.config.plan.kind
    if kind == "optimal" or not len(q_cal):
        return q_cal
    kin_t = tracker_kinematics(cell)
    if kind == "adaptive":
        q = np.radians([p.q_deg for p in plan.candidates])
        n = min(len(q), cell.config.plan.max_points)
        seen = np.any(np.all(np.isclose(q[:, None], q_cal[None]), axis=2), axis=1)         # the seed's poses
        if RULE == "f":
            X = lever_scaled(kin_t, q)
            cover = covered_task(cell, task_poses(cell, q, np.array([p.p_base_mm for p in plan.candidates])))
            X_task = None if cover is None else lever_scaled(kin_t, cover, q)
            rest = choose_batch([], n - len(q_cal), ~seen, "f", Coverage(X, lever_scaled(kin_t, q_cal, q),
                                                                        X_task)).chosen
        else:
            crit = criterion(kin_t, q, pose_covariance(cell, kin_t, q), cell.payload_kg)
            rest = [i for i in d_optimal(crit.A, n, crit.spread).chosen if not seen[i]]
        return np.concatenate([q_cal, q[rest][: n - len(q_cal)]])
    crit = criterion(kin_t, q_cal, pose_covariance(cell, kin_t, q_cal), cell.payload_kg)
    return q_cal[greedy_order(crit.A, len(q_cal), spread=crit.spread)]


def forecast_curve(cell: CellModel, plan: Plan) -> tuple[tuple[int, float], ...]:
    """((n, predicted held-out RMS mm), ...) for n in ``SIZES`` up to the plan's calibration count (and at it)."""
    q = plan_order(cell, plan)
    if len(q) == 0:
        return ()
    q_test = np.radians([p.q_deg for p in plan.points if p.set == "test"]).reshape(-1, q.shape[1])
    sizes = sorted({s for s in SIZES if s < len(q)} | {len(q)})
    return tuple(zip(sizes, forecast_rms(cell, q, q_test if len(q_test) else q, sizes)))


def forecast_rms(cell: CellModel, q_order: np.ndarray, q_test: np.ndarray, sizes) -> list[float]:
    """Predicted held-out RMS (mm) at the test poses q_test (T, n) rad of the model fitted on the first n of the
    calibration poses q_order (N, n), for every n in ``sizes`` (ascending): the module docstring's forecast."""
    kin_t = tracker_kinematics(cell)
    crit = criterion(kin_t, q_order, pose_covariance(cell, kin_t, q_order), cell.payload_kg)
    effects = criterion_effects(kin_t, q_order, cell.payload_kg)
    J, _, prior = design_columns(kin_t, q_test, {"payload_kg": np.full(len(q_test), cell.payload_kg)}, effects)
    cov_test = pose_covariance(cell, kin_t, q_test)
    floor = float(np.sqrt(np.mean(np.trace(cov_test, axis1=1, axis2=2))))
    return [float(r) for r in learning_curve(crit.A, J * prior, floor, sizes)]
