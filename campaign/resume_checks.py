"""Content checks of a run log before ``campaign run --resume`` moves the robot.

The CRC proves a record was written whole, not that its content makes sense. Resume relies on every point
record (which plan points are done, and later the whole log becomes the dataset), so each one is checked
against the plan and the config first: point id in the plan and not repeated, set and commanded joints equal
to the plan's, read-back joints finite and near the limits, xyz finite and a plausible size, covariance 3x3.
The first bad record is a :class:`campaign.runlog.RunLogError` naming its line: exit 2, nothing moves.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from .runlog import LOG_NAME, RunLogError, read_log

Q_CMD_TOL_DEG = 1e-5            # the log stores the plan's joints (rounded to 1e-6 deg)
Q_READ_MARGIN_DEG = 5.0         # read-back joints may sit slightly outside the limits, not more
MAX_ABS_MM = 1.0e6


def _finite_list(value: Any, n: int) -> bool:
    return (isinstance(value, list) and len(value) == n
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))


def _nest_problem(rec: dict, pid: str) -> str | None:
    """Why one nest record cannot be trusted (None when it is fine): its nest id and its reading."""
    if not isinstance(rec.get("nest_id"), str) or not rec["nest_id"] or not pid.startswith(rec["nest_id"] + "@"):
        return f"{pid}: nest record with nest_id {str(rec.get('nest_id'))[:40]!r}"
    p = rec.get("p_tracker_mm")
    if not _finite_list(p, 3) or max(abs(v) for v in p) > MAX_ABS_MM:
        return f"{pid}: p_tracker_mm must be 3 finite numbers below {MAX_ABS_MM:.0e} mm, got {str(p)[:60]}"
    return None


def record_problem(rec: dict, plan_points: dict, lo: list[float], hi: list[float], seen: set[str]) -> str | None:
    """Why one point record cannot be trusted (None when it is fine)."""
    n = len(lo)
    pid = rec.get("point_id")
    if not isinstance(pid, str) or not pid:
        return f"point_id must be non-empty text, got {pid!r}"[:200]
    if pid not in plan_points:
        return f"point_id {pid[:80]!r} is not in the run's plan"
    if pid in seen:
        return f"point_id {pid!r} measured twice"
    planned = plan_points[pid]
    if rec.get("set") != planned.set:
        return f"{pid}: set {str(rec.get('set'))[:40]!r}, the plan says {planned.set!r}"
    if planned.set == "nest":                                # a reference-nest reading: no joints (the robot waited)
        return _nest_problem(rec, pid)
    q_cmd = rec.get("q_cmd_deg")
    if not _finite_list(q_cmd, n):
        return f"{pid}: q_cmd_deg must be {n} finite numbers"
    if max(abs(a - b) for a, b in zip(q_cmd, planned.q_deg)) > Q_CMD_TOL_DEG:
        return f"{pid}: q_cmd_deg differs from the plan's joints"
    q_read = rec.get("q_read_deg", q_cmd)
    if not _finite_list(q_read, n):
        return f"{pid}: q_read_deg must be {n} finite numbers"
    for j, (q, a, b) in enumerate(zip(q_read, lo, hi)):
        if not a - Q_READ_MARGIN_DEG <= q <= b + Q_READ_MARGIN_DEG:
            return f"{pid}: q_read_deg[{j}] = {q:.6g} deg is outside joint {j + 1}'s limits [{a:g}, {b:g}]"
    for key in ("p_tracker_mm", "p2_tracker_mm", "p3_tracker_mm"):
        if key == "p_tracker_mm" or key in rec:
            p = rec.get(key)
            if not _finite_list(p, 3) or max(abs(v) for v in p) > MAX_ABS_MM:
                return f"{pid}: {key} must be 3 finite numbers below {MAX_ABS_MM:.0e} mm, got {str(p)[:60]}"
    cov = rec.get("cov_mm2")
    if cov is not None and not (isinstance(cov, list) and len(cov) == 3 and all(_finite_list(r, 3) for r in cov)):
        return f"{pid}: cov_mm2 must be a 3x3 matrix of finite numbers"
    return None


def _plan_csv(run_dir: Path) -> list:
    """The plan as the run wrote it (RUN_DIR/plan.csv), for checks before the plan is rebuilt."""
    import csv

    from .plan import PlanPoint

    path = run_dir / "plan.csv"
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
        n = sum(1 for h in rows[0] if h[:1] == "q" and h[1:].isdigit())
        return [PlanPoint(r[0], r[1], tuple(float(v) for v in r[2:2 + n]), tuple(float(v) for v in r[2 + n:5 + n]))
                for r in rows[1:]]
    except (OSError, UnicodeDecodeError, IndexError, ValueError, csv.Error):
        raise RunLogError(str(path), "missing or unreadable plan.csv: not a resumable run directory") from None


def check_resume(run_dir: str | Path, cfg, plan=None) -> None:
    """Every point record of RUN_DIR's log is checked against the plan (``plan``, or RUN_DIR/plan.csv when
    None, so that a bad log is refused before the plan is even built) and ``cfg`` before anything moves; then
    the whole log must convert to a dataset (as it will at the end of the run)."""
    from .log_dataset import dataset_from_log

    from .errors import CampaignError

    path = Path(run_dir) / LOG_NAME
    if not path.is_file():
        raise RunLogError(str(path), "no run log here: not a run directory (nothing to resume)")
    contents = read_log(run_dir)
    if contents.start.get("config_sha256") != cfg.sha256:
        raise CampaignError(f"{run_dir}: the config file changed since the run started; resume with the same config")
    if plan is not None and contents.start.get("plan_sha256") != plan.sha256:
        raise CampaignError(f"{run_dir}: the plan differs from the one the run started with")
    lines = contents.point_lines
    plan_points = {p.point_id: p for p in (plan.points if plan is not None else _plan_csv(Path(run_dir)))}
    lo = [j.q_min_deg for j in cfg.robot.joints]
    hi = [j.q_max_deg for j in cfg.robot.joints]
    seen: set[str] = set()
    for k, rec in enumerate(contents.points):
        problem = record_problem(rec, plan_points, lo, hi, seen)
        if problem:
            line = lines[k] if k < len(lines) else None
            raise RunLogError(str(path), f"{problem}: the log cannot be resumed (nothing was moved)", line=line)
        seen.add(rec["point_id"])
    contents.records()                       # every field of every record typed and checked (line and field named)
    if contents.points:
        dataset_from_log(contents)
