"""Motion safety of a campaign: keep-out boxes and the envelope along the swept path, via poses, caps.

The planner and the runner share one ``PathGuard``: the flange origin and every SMR centre must stay
``plan.clearance_mm`` away from every ``plan.keep_out`` box and inside ``plan.envelope`` along the whole
joint-interpolated path between consecutive poses (proven on the continuous path, ``robocal.kinematics.sweep``).
A blocked move gets one or two via poses (the reference configuration, blends towards it, other planned
poses), or one of the next points is visited first; when neither works the plan is refused naming the pair of
points. The runner checks every move
again, and routes the first move from wherever the robot stands.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.errors import CampaignError, ConfigError
from drivers.base import MotionLimits, Payload
from robocal.kinematics.models import Kinematics
from robocal.kinematics.sweep import Boxes, check_segments, clearances_mm, flange_points_base

from .points import PlanPoint

CHUNK = 16                # via candidates checked per batch
REORDER_WINDOW = 4        # later points tried first when no via clears a move
N_NEAREST = 64            # planned poses tried as via candidates


class UnsafeMotion(CampaignError):
    """A move would enter a keep-out box or leave the envelope and no via route was found."""


def motion_limits(cfg: CampaignConfig, speed_pct: float = 100.0) -> MotionLimits:
    """The configured caps, optionally scaled (reduced-speed first pass)."""
    r = cfg.robot
    return MotionLimits(r.max_tcp_speed_mm_s * speed_pct / 100.0, r.max_joint_speed_pct * speed_pct / 100.0)


def payload(cfg: CampaignConfig) -> Payload:
    return Payload(cfg.tool.payload_kg, tuple(cfg.tool.payload_cog_flange_mm))


@dataclass(frozen=True)
class PathGuard:
    """Keep-out / envelope checker of one robot model; joint values in deg at the interface."""
    kin: Kinematics
    p_flange_points_mm: np.ndarray          # (P, 3): flange origin + SMR centres
    keep_out: Boxes
    names: tuple[str, ...]
    envelope: Boxes | None
    envelope_name: str
    clearance_mm: float
    q_home_deg: np.ndarray                  # the plan's reference configuration (first via candidate)

    @classmethod
    def for_cell(cls, cell: CellModel) -> "PathGuard | None":
        """The guard of the cell's nominal model; None when its config has neither keep-out boxes nor an envelope."""
        cfg, kin = cell.config, cell.kinematics
        pl = cfg.plan
        if not pl.keep_out and pl.envelope is None:
            return None
        pts = np.vstack([np.zeros(3), np.asarray(cfg.tool.smrs_mm, float)])
        lo = np.array([b.min_mm for b in pl.keep_out], float).reshape(-1, 3)
        hi = np.array([b.max_mm for b in pl.keep_out], float).reshape(-1, 3)
        env = None if pl.envelope is None else Boxes(np.array([pl.envelope.min_mm], float),
                                                     np.array([pl.envelope.max_mm], float))
        return cls(kin, pts, Boxes(lo, hi), tuple(b.name for b in pl.keep_out), env,
                   "" if pl.envelope is None else pl.envelope.name, pl.clearance_mm,
                   np.asarray(pl.q_ref_deg, float))

    # -- poses
    def pose_reasons(self, q_deg: np.ndarray) -> list[str | None]:
        """Per pose (N, n) deg: why it is not a safe stop (within the clearance of a keep-out box or of the
        envelope's faces), None when it is."""
        q = np.radians(np.atleast_2d(q_deg))
        env = None if self.envelope is None else self.envelope.grown(-self.clearance_mm)
        d, which = clearances_mm(flange_points_base(self.kin, q, self.p_flange_points_mm),
                                 self.keep_out.grown(self.clearance_mm), env)
        return [None if di > 0 else f"within {self.clearance_mm:g} mm of {self.describe(int(w))}"
                for di, w in zip(d, which)]

    # -- segments
    def blocked(self, q_a_deg: np.ndarray, q_b_deg: np.ndarray):
        """robocal.kinematics.sweep.Violation of the segments (M, n) -> (M, n) deg."""
        return check_segments(self.kin, np.radians(q_a_deg), np.radians(q_b_deg), self.p_flange_points_mm,
                              self.keep_out, self.envelope, self.clearance_mm)

    def describe(self, box: int) -> str:
        return f"keep-out box {self.names[box]!r}" if box >= 0 else f"the envelope {self.envelope_name!r} faces"

    def route(self, q_a_deg, q_b_deg, others_deg: np.ndarray | None = None) -> list[tuple[float, ...]]:
        """Via poses (deg) making a -> b safe: [] when the direct path is clear, else one or two vias chosen
        from the reference pose, blends of a and b towards it and ``others_deg`` (planned poses). Raises
        UnsafeMotion when no route is found."""
        a, b = np.asarray(q_a_deg, float), np.asarray(q_b_deg, float)
        v = self.blocked(a[None], b[None])
        if not v.blocked[0]:
            return []
        here = self.pose_reasons(a)[0]
        if here is not None:
            raise UnsafeMotion(f"the robot stands {here}: jog it clear before moving")
        c = self._candidates(a, b, others_deg)
        if len(c):
            cost = np.abs(c - a).max(axis=1) + np.abs(b - c).max(axis=1)
            c = c[np.argsort(cost, kind="stable")]                     # cheapest first
            first = np.zeros(len(c), bool)
            second = np.zeros(len(c), bool)
            for lo in range(0, len(c), CHUNK):                         # one via: stop at the first chunk that works
                cc = c[lo:lo + CHUNK]
                first[lo:lo + CHUNK] = ~self.blocked(np.broadcast_to(a, cc.shape), cc).blocked
                second[lo:lo + CHUNK] = ~self.blocked(cc, np.broadcast_to(b, cc.shape)).blocked
                one = np.flatnonzero(first[lo:lo + CHUNK] & second[lo:lo + CHUNK])
                if len(one):
                    return [tuple(np.round(cc[one[0]], 6))]
            i1, i2 = np.flatnonzero(first)[:12], np.flatnonzero(second)[:12]   # two vias, cheapest legs
            if len(i1) and len(i2):
                I, J = (x.ravel() for x in np.meshgrid(i1, i2, indexing="ij"))
                mid = ~self.blocked(c[I], c[J]).blocked
                if mid.any():
                    tot = (np.abs(c[I] - a).max(axis=1) + np.abs(c[J] - c[I]).max(axis=1)
                           + np.abs(b - c[J]).max(axis=1))
                    k = np.flatnonzero(mid)[np.argmin(tot[mid])]
                    return [tuple(np.round(c[I[k]], 6)), tuple(np.round(c[J[k]], 6))]
        raise UnsafeMotion(f"the joint move would pass {self.describe(int(v.box[0]))} (at {100 * v.s[0]:.0f} % of "
                           f"the path) and no via pose clears it")

    def _candidates(self, a: np.ndarray, b: np.ndarray, others: np.ndarray | None) -> np.ndarray:
        """Via candidates (K, n) deg: home, blends of a and b towards home, the planned poses nearest to a and b."""
        h = self.q_home_deg
        t = np.array([0.25, 0.5, 0.75, 1.0])[:, None]
        cands = [h[None], a + t * (h - a), b + t * (h - b)]
        if others is not None and len(others):
            o = np.asarray(others, float)
            d = np.minimum(np.abs(o - a).max(axis=1), np.abs(o - b).max(axis=1))
            cands.append(o[np.argsort(d)[:N_NEAREST]])
        c = np.unique(np.vstack(cands).round(6), axis=0)
        keep = np.array([r is None for r in self.pose_reasons(c)]) if len(c) else np.zeros(0, bool)
        lo, hi = np.degrees(self.kin.q_min_rad), np.degrees(self.kin.q_max_rad)
        keep &= np.all((c >= lo) & (c <= hi), axis=1)
        return c[keep]


def plan_route(guard: PathGuard, q_deg: np.ndarray, ids: Sequence[str],
               reorder: int = REORDER_WINDOW) -> tuple[list[int], list[tuple[tuple[float, ...], ...]]]:
    """Visiting order and via poses of the planned poses (N, n) deg. A move that no via pose clears is avoided by
    visiting one of the next ``reorder`` points first (when both new moves can be made safe); otherwise
    UnsafeMotion names the pair of points. Returns (order (N,) indices, vias per visited point)."""
    q = np.asarray(q_deg, float)
    n = len(q)
    if n < 2:
        return list(range(n)), [()] * n
    direct = ~guard.blocked(q[:-1], q[1:]).blocked        # one batched check; only blocked pairs are searched
    order, vias, todo = [0], [()], list(range(1, n))
    while todo:
        a, b = order[-1], todo.pop(0)
        if b == a + 1 and direct[a]:
            order.append(b)
            vias.append(())
            continue
        try:
            vias.append(tuple(guard.route(q[a], q[b], q)))
            order.append(b)
            continue
        except UnsafeMotion as exc:
            failure = exc
        for j in todo[:reorder]:                          # visit a later point first, then come back to b
            try:
                v1, v2 = tuple(guard.route(q[a], q[j], q)), tuple(guard.route(q[j], q[b], q))
            except UnsafeMotion:
                continue
            todo.remove(j)
            order += [j, b]
            vias += [v1, v2]
            break
        else:
            raise UnsafeMotion(f"no safe path from point {ids[a]} to point {ids[b]}: {failure}")
    return order, vias


def with_vias(cfg: CampaignConfig, guard: PathGuard, points: list[PlanPoint]) -> list[PlanPoint]:
    """Via poses where the swept path between consecutive points is blocked, or a point visited a little later;
    ConfigError naming the pair of points when neither works."""
    try:
        order, vias = plan_route(guard, np.array([p.q_deg for p in points]), [p.point_id for p in points])
    except UnsafeMotion as exc:
        raise ConfigError(cfg.source_path, "plan.keep_out", str(exc)) from None
    return [replace(points[i], via_deg=v) if v else points[i] for i, v in zip(order, vias)]
