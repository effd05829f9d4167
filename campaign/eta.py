"""Campaign duration: predicted from the motion caps and the tracker's reading time, refined during the run.

Per point: the moves (via poses included) at the capped speeds (``robocal.sweep.move_durations_s`` on the
nominal model, the same timing law the mock controller uses), the settle time and ``samples`` x
``reading_time_s`` per SMR. During a run, the ratio of measured to predicted point times (move + settle +
readings, from the log records) scales the prediction of the remaining points.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from robocal.kinematics import Kinematics
from robocal.sweep import move_durations_s

from .config import CampaignConfig
from .plan import PlanPoint


def point_durations_s(points: Sequence[PlanPoint], cfg: CampaignConfig, kin: Kinematics,
                      q_start_deg: Sequence[float] | None = None) -> np.ndarray:
    """(N,) predicted seconds per point, in plan order, starting from ``q_start_deg`` (default ``plan.q_ref_deg``)."""
    if not points:
        return np.zeros(0)
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
    t_move = move_durations_s(kin, np.radians(q_from), np.radians(q_to), p_pts,
                              np.radians(r.max_joint_speed_deg_s) * r.max_joint_speed_pct / 100.0,
                              r.max_tcp_speed_mm_s)
    m = cfg.tracker.measurement
    per_point = m.settle_s + m.samples * m.reading_time_s * len(cfg.tool.smrs_mm)
    return np.bincount(owner, weights=t_move, minlength=len(points)) + per_point


def estimate_duration_s(points: Sequence[PlanPoint], cfg: CampaignConfig, kin: Kinematics) -> float:
    """Predicted campaign duration (s), including the reduced-speed first pass when configured."""
    total = float(point_durations_s(points, cfg, kin).sum())
    pct = cfg.robot.first_pass_speed_pct
    if pct and points:
        m = cfg.tracker.measurement
        moves = total - len(points) * (m.settle_s + m.samples * m.reading_time_s * len(cfg.tool.smrs_mm))
        total += moves * 100.0 / pct
    return total


class RunEta:
    """Remaining time of a run: the prediction scaled by measured / predicted time of the points done so far."""

    def __init__(self, predicted_s: np.ndarray) -> None:
        self.predicted_s = np.asarray(predicted_s, float)
        self.done = 0
        self.actual_sum_s = 0.0
        self.predicted_sum_s = 0.0

    @classmethod
    def for_plan(cls, points: Sequence[PlanPoint], cfg: CampaignConfig, kin: Kinematics) -> "RunEta":
        return cls(point_durations_s(points, cfg, kin))

    def observe(self, record: dict) -> None:
        """A measured point record (``t_start_s`` before its move, ``t_end_s`` after its last reading)."""
        if self.done < len(self.predicted_s):
            self.actual_sum_s += max(0.0, float(record["t_end_s"]) - float(record["t_start_s"]))
            self.predicted_sum_s += self.predicted_s[self.done]
        self.done += 1

    @property
    def ratio(self) -> float:
        return self.actual_sum_s / self.predicted_sum_s if self.predicted_sum_s > 0 else 1.0

    def remaining_s(self) -> float:
        return self.ratio * float(self.predicted_s[self.done:].sum())

    def text(self) -> str:
        s = int(round(self.remaining_s()))
        return f"ETA {s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"
