"""The durable log (``log.jsonl`` records) as a :class:`campaign.data.dataset.Dataset`, checked field by field."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from campaign.errors import DataError

from .dataset import SETS, Dataset  # noqa: F401
from .interchange_csv import _check_ids

def _sigma_from(rec: dict) -> float | None:
    """1-sigma in mm: ``sigma_mm``, else sqrt(trace(cov_mm2)/3) (RMS per axis)."""
    if rec.get("sigma_mm") is not None:
        return float(rec["sigma_mm"])
    cov = rec.get("cov_mm2")
    if cov is None:
        return None
    cov = np.asarray(cov, dtype=np.float64)
    variances = np.diag(cov) if cov.ndim == 2 else cov.reshape(-1)
    return float(np.sqrt(np.mean(variances)))


def _temp_from(rec: dict) -> Any:
    """``temperatures["temp_c"]`` if present, else a top-level ``temp_c``."""
    temps = rec.get("temperatures")
    if isinstance(temps, dict) and temps.get("temp_c") is not None:
        return temps["temp_c"]
    return rec.get("temp_c")


_LOG_FIELDS: dict[str, Callable[[dict], Any]] = {
    "t_s": lambda r: r.get("t_end_s"),
    "temp_c": _temp_from,
    "payload_kg": lambda r: r.get("payload_kg"),
    "p2_tracker_mm": lambda r: r.get("p2_tracker_mm"),
    "p3_tracker_mm": lambda r: r.get("p3_tracker_mm"),
    "sigma_mm": _sigma_from,
}


def _optional(values: list, name: str, where: Callable[[int], str], src: str) -> list | None:
    """All present -> the list; none present -> None; a mix -> DataError."""
    missing = [i for i, v in enumerate(values) if v is None]
    if len(missing) == len(values):
        return None
    if missing:
        raise DataError(src, f"{where(missing[0])}: has no '{name}' while other points do")
    return values


def _log_set(rec: dict, where: str, src: str) -> str:
    """``check`` for check-pose records, else the record's ``set``."""
    set_name = "check" if rec.get("kind") == "check" else rec.get("set")
    if set_name not in SETS:
        raise DataError(src, f"{where}: set must be calib, test, check or nest, got {set_name!r}")
    if set_name == "nest" and not str(rec.get("nest_id") or ""):
        raise DataError(src, f"{where}: a nest record without 'nest_id'")
    return set_name


def _env_from(key: str) -> Callable[[dict], Any]:
    """``temperatures[key]`` (the tracker's environment readings) or None."""
    def get(rec: dict) -> Any:
        temps = rec.get("temperatures")
        return temps.get(key) if isinstance(temps, dict) else None
    return get


_ENV_KEYS = {"env_temp_c": "temp_c", "env_pressure_hpa": "pressure_hpa", "env_humidity_pct": "humidity_pct"}


def _with_nan(values: list, robot: list[bool], width: int | None) -> list:
    """Robot-row values kept, nest rows NaN (a scalar, or a row of ``width``)."""
    blank = math.nan if width is None else [math.nan] * width
    return [v if r else blank for v, r in zip(values, robot)]


def _log_q(rec: dict, where: str, src: str) -> list:
    """``q_read_deg`` when recorded, else ``q_cmd_deg``."""
    q = rec.get("q_read_deg")
    if q is None:
        q = rec.get("q_cmd_deg")
    if q is None:
        raise DataError(src, f"{where}: has neither 'q_read_deg' nor 'q_cmd_deg'")
    return q


def _spread(values: list, idx: list[int], n: int) -> list:
    """A list of length ``n`` with ``values`` at the positions ``idx`` (None elsewhere)."""
    out: list = [None] * n
    for i, v in zip(idx, values):
        out[i] = v
    return out


def dataset_from_log(contents: Any) -> Dataset:
    """Convert the ``point`` records of a run log into a :class:`Dataset`.

    ``contents`` is a :class:`campaign.run.log_reader.LogContents`.  Rows are in log
    order, check-pose records (``kind == "check"``) get set ``check``.
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
    src = getattr(contents, "path", "") or "<run log>"
    recs = list(contents.points)
    if not recs:
        raise DataError(src, "no data rows (no point records)")

    def where(i: int) -> str:
        return f"point record {i + 1} (point_id {recs[i].get('point_id')!r})"

    ids = [str(r.get("point_id", "")) for r in recs]
    sets = [_log_set(r, where(i), src) for i, r in enumerate(recs)]
    _check_ids(
        ids,
        sets,
        lambda i, what: DataError(src, f"point record {i + 1}: {what}"),
        lambda k: f"in point record {k + 1}",
    )
    robot = [s != "nest" for s in sets]
    idx = [i for i, r in enumerate(robot) if r]
    if not idx:
        raise DataError(src, "no data rows (only nest records)")
    q = [_log_q(recs[i], where(i), src) for i in idx]
    widths = {len(v) for v in q}
    if len(widths) != 1:
        raise DataError(src, f"point records have different joint counts {sorted(widths)}")
    n_joints = widths.pop()
    p = [r.get("p_tracker_mm") for r in recs]
    if any(v is None for v in p):
        raise DataError(src, f"{where(p.index(None))}: has no 'p_tracker_mm'")
    rob = [recs[i] for i in idx]
    back = lambda values: _with_nan(_spread(values, idx, len(recs)), robot, None)  # noqa: E731
    try:
        extra: dict[str, Any] = {}
        for name, get in _LOG_FIELDS.items():
            if name in ("t_s", "sigma_mm"):           # nest records have them too
                extra[name] = _optional([get(r) for r in recs], name, where, src)
                continue
            values = [get(r) for r in rob]
            if name == "temp_c" and None in values and all(r.get("temp_c") is None for r in rob):
                continue    # tracker weather readings with gaps (a failed read): kept as env_temp_c with NaN
            got = _optional(values, name, lambda k: where(idx[k]), src)
            if got is not None:
                width = 3 if name.endswith("_tracker_mm") else None
                extra[name] = _with_nan(_spread(got, idx, len(recs)), robot, width)
        if extra["t_s"] is not None:
            t = np.asarray(extra["t_s"], dtype=np.float64)
            extra["t_s"] = t - t[0]
        elif not all(robot):
            raise DataError(src, "nest records need 't_end_s' (drift is a function of time)")
        if all(r.get("q_read_deg") is not None and r.get("q_cmd_deg") is not None for r in rob):
            extra["qc_deg"] = _with_nan(_spread([r["q_cmd_deg"] for r in rob], idx, len(recs)), robot, n_joints)
        for name, key in _ENV_KEYS.items():
            env = [_env_from(key)(r) for r in recs]
            if any(v is not None for v in env):
                extra[name] = [math.nan if v is None else v for v in env]
        if not all(robot):
            extra["nest_id"] = tuple("" if r else str(rec.get("nest_id")) for r, rec in zip(robot, recs))
        q_all = _with_nan(_spread(q, idx, len(recs)), robot, n_joints)
        device = [r.get("cov_mm2") if r.get("cov_source") == "device" else None for r in rob]
        if all(v is not None for v in device):             # all robot rows or none; nest rows: their logged cov
            extra["cov_mm2"] = [r.get("cov_mm2") or [[math.nan] * 3] * 3 for r in recs]
        return Dataset(tuple(ids), tuple(sets), q_all, p, source=src, **extra)
    except DataError:
        raise
    except (TypeError, ValueError) as exc:
        raise DataError(src, f"point records: {exc}") from None
