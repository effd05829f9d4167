"""Campaign duration: predicted from the motion caps and the tracker's reading time, refined during the run.

Per point: the moves (via poses included) at the capped speeds (``robocal.kinematics.sweep.move_durations_s`` on the
nominal model, the same timing law the mock controller uses), the settle time and ``samples`` x
``reading_time_s`` per SMR. During a run, the ratio of measured to predicted point times (move + settle +
readings, from the log records) scales the prediction of the remaining points.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from robocal.kinematics.sweep import move_durations_s

from campaign.config.cell_model import CellModel
from campaign.plan.points import PlanPoint
from .log_records import NestRecord, PointRecord


def point_times_s(points: Sequence[PlanPoint], cell: CellModel,
                  q_start_deg: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predicted (move + settle, readings) seconds per point (N,) each: moves of the nominal model at the capped
    speeds, the settle time, and samples x reading_time_s per SMR."""
    cfg = cell.config
    m = cfg.tracker.measurement
    if not points:
        return np.zeros(0), np.zeros(0)
    prev = np.asarray(cfg.plan.q_ref_deg if q_start_deg is None else q_start_deg, float)
    q_from, q_to, owner = [], [], []
    for i, p in enumerate(points):
        for q in (*p.via_deg, p.q_deg):
            q_from.append(prev)
            q_to.append(q)
            owner.append(i)
            prev = np.asarray(q, float)
    r = cfg.robot
    p_pts = np.vstack([np.zeros(3), np.asarray(cfg.tool.smrs_mm, float)])
    t_move = move_durations_s(cell.kinematics, np.radians(q_from), np.radians(q_to), p_pts,
                              np.radians(r.max_joint_speed_deg_s) * r.max_joint_speed_pct / 100.0,
                              r.max_tcp_speed_mm_s)
    move = np.bincount(owner, weights=t_move, minlength=len(points)) + m.settle_s
    return move, np.full(len(points), m.samples * m.reading_time_s * len(cfg.tool.smrs_mm))


def estimate_duration_s(points: Sequence[PlanPoint], cell: CellModel) -> float:
    """Predicted campaign duration (s), including the reduced-speed first pass when configured."""
    cfg = cell.config
    move, fixed = point_times_s(points, cell)
    total = float(move.sum() + fixed.sum())
    pct = cfg.robot.first_pass_speed_pct
    if pct and points:
        total += float(move.sum() - len(points) * cfg.tracker.measurement.settle_s) * 100.0 / pct
    return total


class RunEta:
    """Remaining time of a run: predicted move and reading times, each scaled by its measured / predicted ratio
    over the points done so far (``t_start_s`` -> ``t_measure_s`` -> ``t_end_s`` of the log records);
    ``simulated``: the cell's clock is a mock cell's (the text says so)."""

    def __init__(self, predicted_move_s: np.ndarray, predicted_read_s: np.ndarray | None = None,
                 simulated: bool = False) -> None:
        self.simulated = simulated              # a mock cell: the times are its simulated clock's
        self.move = np.asarray(predicted_move_s, float)
        self.read = np.zeros_like(self.move) if predicted_read_s is None else np.asarray(predicted_read_s, float)
        self.done = 0
        self.sums = np.zeros(4)              # measured move, predicted move, measured reading, predicted reading

    def observe(self, record: PointRecord | NestRecord) -> None:
        """A measured point record (``t_start_s`` before its move, ``t_measure_s`` settled, ``t_end_s`` after the
        last reading; a nest reading has no move)."""
        if self.done < len(self.move):
            t0, t2 = float(record.t_start_s), float(record.t_end_s)
            t1 = getattr(record, "t_measure_s", None)            # nest readings and earlier logs: no split
            t1 = t0 if t1 is None else float(t1)
            self.sums += (max(0.0, t1 - t0), self.move[self.done], max(0.0, t2 - t1), self.read[self.done])
        self.done += 1

    def skip(self, n: int) -> None:
        """The next ``n`` planned points will not be measured (a stop rule dropped them)."""
        self.move = np.concatenate([self.move[: self.done], self.move[self.done + n:]])
        self.read = np.concatenate([self.read[: self.done], self.read[self.done + n:]])

    def remaining_s(self) -> float:
        m, pm, r, pr = self.sums
        k_move = m / pm if pm > 0 else 1.0
        k_read = r / pr if pr > 0 else 1.0
        return float(k_move * self.move[self.done:].sum() + k_read * self.read[self.done:].sum())

    def text(self) -> str:
        """``ETA h:mm:ss``, labelled ``(simulated time)`` on a mock cell."""
        s = int(round(self.remaining_s()))
        return f"ETA {s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" + (" (simulated time)" if self.simulated else "")


def grid_duration_s(cell: CellModel) -> float:
    """Predicted duration (s) of the config's full grid plan (``plan.kind: grid``: its grid, test set, check poses and
    nests), what an optimal or adaptive plan is compared with."""
    from dataclasses import replace

    from campaign.plan.build import build_plan

    cfg = cell.config
    grid = replace(cell, config=replace(cfg, plan=replace(cfg.plan, kind="grid", stop="off", points=None,
                                                          max_points=None)))
    return estimate_duration_s(build_plan(grid).points, grid)


def budget_duration_s(points: Sequence[PlanPoint], cell: CellModel) -> float:
    """Predicted duration (s) of an adaptive plan measured to its whole pose budget: its planned points, and every
    calibration point up to ``plan.max_points`` beyond its seed at the seed points' mean time."""
    move, fixed = point_times_s(points, cell)
    seed = np.array([p.set == "calib" for p in points])
    extra = max(0, (cell.config.plan.max_points or 0) - int(seed.sum()))
    per = float(np.mean(move[seed] + fixed[seed])) if seed.any() else 0.0
    return estimate_duration_s(points, cell) + extra * per
