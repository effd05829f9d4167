"""The measurement plan as data: ``PlanPoint`` (id, set, joints, position, via poses), ``Skipped``, ``Plan`` (points
in motion order, hash, blocks) and ``plan.csv``."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class PlanPoint:
    """One measurement: id, set (calib | test | check | nest), commanded joints (deg), target SMR position (mm, base),
    and the via poses (deg) the robot passes on its way there (keep-out boxes; usually none). A ``nest`` point is a
    tracker reading of a fixed nest: ``p_base_mm`` is the nest's approximate position and ``q_deg`` where the robot
    waits meanwhile (the previous point's joints; the runner never moves for a nest)."""
    point_id: str
    set: str
    q_deg: tuple[float, ...]
    p_base_mm: tuple[float, float, float]
    via_deg: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class Skipped:
    point_id: str
    set: str
    p_base_mm: tuple[float, float, float]
    reason: str


@dataclass(frozen=True)
class Plan:
    """The measurement sequence, the targets that could not be planned, the hash of the sequence, and (``stop:
    auto`` plans) the calibration-point counts at which the run may stop (``blocks``, ascending). An adaptive plan
    also holds its ``candidates``: calibration poses, each checked like a planned one, that its rounds may add."""
    points: tuple[PlanPoint, ...]
    skipped: tuple[Skipped, ...]
    sha256: str
    blocks: tuple[int, ...] = ()
    candidates: tuple[PlanPoint, ...] = ()

    def known_points(self) -> dict[str, PlanPoint]:
        """Every point a run of this plan may measure, by id: the sequence and the candidates."""
        return {**{p.point_id: p for p in self.candidates}, **{p.point_id: p for p in self.points}}

    def count(self, set_name: str) -> int:
        return sum(p.set == set_name for p in self.points)



CANDIDATE = "candidate"          # plan.csv's set of an adaptive plan's candidate poses (measured as "calib")


def nest_point_id(nest_id: str, round_no: int) -> str:
    """Plan/log id of round ``round_no`` (1-based) of nest ``nest_id``."""
    return f"{nest_id}@{round_no:03d}"


def write_plan_csv(plan: Plan, path: str | Path) -> None:
    """Write :func:`plan_csv_text` atomically."""
    from campaign.io.durable import atomic_write

    atomic_write(path, plan_csv_text(plan).encode("utf-8"))


def plan_csv_text(plan: Plan) -> str:
    """point_id,set,q1..qn (deg),x_base_mm,y_base_mm,z_base_mm in motion order; via poses as rows of set ``via``
    (id ``POINT.viaK``, no position) before the point they lead to; nest rows: where the
    robot waits, the nest's approximate position; an adaptive plan's candidates last, as rows of set
    ``candidate``."""
    from campaign.io.csv_cells import render_rows

    n = len(plan.points[0].q_deg) if plan.points else 0

    def rows():
        for p in plan.points:
            for k, via in enumerate(p.via_deg):              # via poses (keep-out): passed through, not measured
                yield [f"{p.point_id}.via{k + 1}", "via", *(f"{v:.6f}" for v in via), "", "", ""]
            yield [p.point_id, p.set, *(f"{v:.6f}" for v in p.q_deg), *(f"{v:.3f}" for v in p.p_base_mm)]
        for p in plan.candidates:
            yield [p.point_id, CANDIDATE, *(f"{v:.6f}" for v in p.q_deg), *(f"{v:.3f}" for v in p.p_base_mm)]

    header = ["point_id", "set"] + [f"q{i + 1}" for i in range(n)] + ["x_base_mm", "y_base_mm", "z_base_mm"]
    return render_rows(header, rows(), text_columns=(0, 1))
