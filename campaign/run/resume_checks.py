"""Content checks of a run log before ``campaign run --resume`` moves the robot.

The CRC proves a record was written whole, not that its content makes sense. Resume relies on every point
record (which plan points are done, and later the whole log becomes the dataset), so each one is first read as
a typed record (:mod:`campaign.run.log_records`: every field present, of its type, finite, of its size) and then checked
against the plan and the config: point id in the plan and not repeated, set and commanded joints equal to the
plan's, read-back joints near the limits, xyz of a plausible size; then the records together (one joint count, an
optional field in all records or none), as the dataset at the end of the run needs them.
The first bad record is a :class:`campaign.run.log_reader.RunLogError` naming its line: exit 2, nothing moves.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

from campaign.io.csv_cells import restore
from campaign.errors import DataError
from .log_records import NestRecord, PointRecord, check_records
from .log_reader import LOG_NAME, RunLogError, read_log

Q_CMD_TOL_DEG = 1e-5            # the log stores the plan's joints (rounded to 1e-6 deg)
Q_READ_MARGIN_DEG = 5.0         # read-back joints may sit slightly outside the limits, not more
MAX_ABS_MM = 1.0e6


def _too_large(p_mm) -> bool:
    return max(abs(v) for v in p_mm) > MAX_ABS_MM


def _nest_problem(rec: NestRecord, pid: str) -> str | None:
    """Why one nest record cannot be trusted (None when it is fine): its nest id and its reading."""
    if not rec.nest_id or not pid.startswith(rec.nest_id + "@"):
        return f"{pid}: nest record with nest_id {rec.nest_id[:40]!r}"
    if _too_large(rec.p_tracker_mm):
        return f"{pid}: p_tracker_mm must be 3 finite numbers below {MAX_ABS_MM:.0e} mm, got {rec.p_tracker_mm}"
    return None


def record_problem(rec: PointRecord | NestRecord, plan_points: dict, lo: list[float], hi: list[float],
                   seen: set[str]) -> str | None:
    """Why one (typed, so well-formed) point record cannot be trusted against the plan and config (None: fine)."""
    n = len(lo)
    pid = rec.point_id
    if not pid:
        return "point_id must be non-empty text, got ''"
    if pid not in plan_points:
        return f"point_id {pid[:80]!r} is not in the run's plan"
    if pid in seen:
        return f"point_id {pid!r} measured twice"
    planned = plan_points[pid]
    if rec.set != planned.set:
        return f"{pid}: set {rec.set[:40]!r}, the plan says {planned.set!r}"
    if isinstance(rec, NestRecord):                          # a reference-nest reading: no joints (the robot waited)
        return _nest_problem(rec, pid)
    if len(rec.q_cmd_deg) != n:
        return f"{pid}: q_cmd_deg must be {n} finite numbers"
    if max(abs(a - b) for a, b in zip(rec.q_cmd_deg, planned.q_deg)) > Q_CMD_TOL_DEG:
        return f"{pid}: q_cmd_deg differs from the plan's joints"
    for j, (q, a, b) in enumerate(zip(rec.q_read_deg, lo, hi)):
        if not a - Q_READ_MARGIN_DEG <= q <= b + Q_READ_MARGIN_DEG:
            return f"{pid}: q_read_deg[{j}] = {q:.6g} deg is outside joint {j + 1}'s limits [{a:g}, {b:g}]"
    for key, p in (("p_tracker_mm", rec.p_tracker_mm), *((f"p{s.k}_tracker_mm", s.p_tracker_mm) for s in rec.smrs)):
        if _too_large(p):
            return f"{pid}: {key} must be 3 finite numbers below {MAX_ABS_MM:.0e} mm, got {str(p)[:60]}"
    return None


def _plan_csv(run_dir: Path) -> list:
    """The plan as the run wrote it (RUN_DIR/plan.csv), for checks before the plan is rebuilt."""
    import csv

    from campaign.plan.points import CANDIDATE, PlanPoint

    path = run_dir / "plan.csv"
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
        n = sum(1 for h in rows[0] if h[:1] == "q" and h[1:].isdigit())
        return [PlanPoint(restore(r[0]), "calib" if restore(r[1]) == CANDIDATE else restore(r[1]),  # measured as calib
                          tuple(float(v) for v in r[2:2 + n]), tuple(float(v) for v in r[2 + n:5 + n]))
                for r in rows[1:]]
    except (OSError, UnicodeDecodeError, IndexError, ValueError, csv.Error):
        raise RunLogError(str(path), "missing or unreadable plan.csv: not a resumable run directory") from None


def check_unchanged(run_dir: str | Path, start: dict, cfg, plan=None) -> None:
    """The config, RUN_DIR/plan.csv and (when given) the rebuilt plan are those the run started with (hashes in
    the start record); DataError naming what changed otherwise (exit 2, nothing moves)."""
    run_dir = Path(run_dir)
    if start.get("config_sha256") != cfg.sha256:
        raise DataError(str(cfg.source_path), f"this is not the config {run_dir} started with (its sha256 differs "
                                              f"from the run's start record): resume with {run_dir / 'config.yaml'}")
    expected = start.get("plan_csv_sha256")                 # absent in runs of earlier versions
    if expected is not None:
        try:
            actual = hashlib.sha256((run_dir / "plan.csv").read_bytes()).hexdigest()
        except OSError:
            actual = None
        if actual != expected:
            raise DataError(str(run_dir / "plan.csv"), "missing or changed since the run started (its sha256 differs "
                                                       "from the run's start record): restore the run's plan.csv")
    if plan is not None and start.get("plan_sha256") != plan.sha256:
        raise DataError(str(run_dir), "the plan built from this config differs from the one the run started with "
                                      "(software or config change): the run cannot be resumed")


def check_resume(run_dir: str | Path, cfg, plan=None) -> None:
    """Every point record of RUN_DIR's log is checked against the plan (``plan``, or RUN_DIR/plan.csv when
    None, so that a bad log is refused before the plan is even built) and ``cfg`` before anything moves; then
    the records together (:func:`campaign.run.log_records.check_records`: what the dataset at the end of the
    run needs)."""
    path = Path(run_dir) / LOG_NAME
    if not path.is_file():
        raise RunLogError(str(path), "no run log here: not a run directory (nothing to resume)")
    contents = read_log(run_dir)
    check_unchanged(run_dir, contents.start, cfg, plan)
    lines = contents.point_lines
    try:
        records = contents.records(cfg.robot.n_joints)  # every field typed and checked (line and field named)
    except RunLogError as exc:
        raise RunLogError(exc.file, f"{exc.message}: the log cannot be resumed (nothing was moved)",
                          line=exc.line) from None
    plan_points = plan.known_points() if plan is not None else {p.point_id: p for p in _plan_csv(Path(run_dir))}
    lo = [j.q_min_deg for j in cfg.robot.joints]
    hi = [j.q_max_deg for j in cfg.robot.joints]
    seen: set[str] = set()
    for k, rec in enumerate(records):
        problem = record_problem(rec, plan_points, lo, hi, seen)
        if problem:
            line = lines[k] if k < len(lines) else None
            raise RunLogError(str(path), f"{problem}: the log cannot be resumed (nothing was moved)", line=line)
        seen.add(rec.point_id)
    try:
        check_records(records, str(path), lines)
    except DataError as exc:
        raise RunLogError(exc.file, f"{exc.message}: the log cannot be resumed (nothing was moved)",
                          line=exc.line) from None
