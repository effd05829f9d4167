"""The durable log (``log.jsonl`` records) as a :class:`campaign.data.dataset.Dataset`, from its typed records."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from campaign.errors import DataError
from campaign.run.log_reader import LogContents
from campaign.run.log_records import OPTIONAL_FIELDS, PointRecord, Record, check_records

from .dataset import Dataset
from .interchange_reader import check_ids

_ENV_KEYS = {"env_temp_c": "temp_c", "env_pressure_hpa": "pressure_hpa", "env_humidity_pct": "humidity_pct"}


def _with_nan(values: list, robot: list[bool], width: int | None) -> list:
    """Robot-row values kept, nest rows NaN (a scalar, or a row of ``width``)."""
    blank = math.nan if width is None else [math.nan] * width
    return [v if r else blank for v, r in zip(values, robot)]


def _spread(values: list, idx: list[int], n: int) -> list:
    """A list of length ``n`` with ``values`` at the positions ``idx`` (None elsewhere)."""
    out: list = [None] * n
    for i, v in zip(idx, values):
        out[i] = v
    return out


def _optional_columns(recs: Sequence[Record], robot: list[bool], idx: list[int]) -> dict[str, Any]:
    """The :data:`OPTIONAL_FIELDS` columns every record has (``check_records`` ruled out a mix): ``t_s`` from
    ``t_end_s`` relative to the first record, robot-only values NaN on nest rows."""
    out: dict[str, Any] = {}
    for field in OPTIONAL_FIELDS:
        rows = range(len(recs)) if field.nests else idx
        values = [field.get(recs[i]) for i in rows]
        if not values or None in values:
            continue
        if field.nests:
            out[field.name] = values
        else:
            width = 3 if field.name.endswith("_tracker_mm") else None
            out[field.name] = _with_nan(_spread(values, idx, len(recs)), robot, width)
    if "t_s" in out:
        t = np.asarray(out["t_s"], dtype=np.float64)
        out["t_s"] = t - t[0]
    return out


def _joints(rec: PointRecord) -> tuple[float, ...]:
    """``q_read_deg`` when recorded, else ``q_cmd_deg``."""
    return rec.q_read_deg if rec.q_read_deg is not None else rec.q_cmd_deg


def dataset_from_log(contents: LogContents) -> Dataset:
    """Convert the ``point`` records of a run log into a :class:`Dataset`.

    ``contents`` is a :class:`campaign.run.log_reader.LogContents`, read as typed records of any log
    (``records(foreign=True)``: older and foreign shapes migrated, e.g. ``kind == "check"`` records get set
    ``check``) and checked together by :func:`campaign.run.log_records.check_records`. Rows are in log order.
    q: ``q_read_deg`` if present else ``q_cmd_deg`` (deg); ``p_tracker_mm``
    (mm); ``t_s`` = ``t_end_s`` minus the first point's ``t_end_s`` (s);
    ``temp_c`` from ``temperatures["temp_c"]`` (or a top-level ``temp_c``);
    ``payload_kg``; ``sigma_mm`` from ``sigma_mm`` or sqrt(trace(cov_mm2)/3);
    ``p2_tracker_mm``/``p3_tracker_mm`` if recorded.  An optional field must
    be in all point records or in none.  Raises :class:`DataError`.
    With both ``q_read_deg`` and ``q_cmd_deg`` in every record, ``q_deg`` is
    the read-back set and ``qc_deg`` the commanded one.  Nest records
    (``set`` nest, ``nest_id``) become nest rows (joints NaN).  The tracker's
    environment (``temperatures``: temp_c, pressure_hpa, humidity_pct) gives
    ``env_temp_c``, ``env_pressure_hpa``, ``env_humidity_pct`` (NaN where not read).
    """
    src = contents.path or "<run log>"
    if not contents.points:
        raise DataError(src, "no data rows (no point records)")
    recs = contents.records(foreign=True)
    lines = contents.point_lines
    check_records(recs, src, lines)
    ids = [r.point_id for r in recs]
    sets = [r.set for r in recs]
    check_ids(
        ids,
        sets,
        lambda i, what: DataError(src, f"point record {i + 1}: {what}", line=lines[i] if i < len(lines) else None),
        lambda k: f"in point record {k + 1}",
    )
    robot = [isinstance(r, PointRecord) for r in recs]
    idx = [i for i, r in enumerate(robot) if r]
    if not idx:
        raise DataError(src, "no data rows (only nest records)")
    rob: list[PointRecord] = [recs[i] for i in idx]
    n_joints = rob[0].n_joints
    try:
        extra = _optional_columns(recs, robot, idx)
        if all(r.q_read_deg is not None and r.q_cmd_deg is not None for r in rob):
            extra["qc_deg"] = _with_nan(_spread([r.q_cmd_deg for r in rob], idx, len(recs)), robot, n_joints)
        for name, key in _ENV_KEYS.items():
            env = [(r.temperatures or {}).get(key) for r in recs]
            if any(v is not None for v in env):
                extra[name] = [math.nan if v is None else v for v in env]
        if not all(robot):
            extra["nest_id"] = tuple("" if r else rec.nest_id for r, rec in zip(robot, recs))
        q_all = _with_nan(_spread([_joints(r) for r in rob], idx, len(recs)), robot, n_joints)
        if all(r.cov_source == "device" and r.cov_mm2 is not None for r in rob):   # all robot rows or none
            blank = [[math.nan] * 3] * 3                                            # nest rows keep theirs
            extra["cov_mm2"] = [r.cov_mm2 if r.cov_mm2 is not None else blank for r in recs]
        p = [r.p_tracker_mm for r in recs]
        return Dataset(tuple(ids), tuple(sets), q_all, p, source=src, **extra)
    except DataError:
        raise
    except (TypeError, ValueError) as exc:
        raise DataError(src, f"point records: {exc}") from None
