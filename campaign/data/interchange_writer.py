"""Writing the interchange CSV (:mod:`campaign.data.interchange_csv`): the canonical column order of a dataset,
its numeric block, and the refusal of data that ``read_csv`` would not read back identically. ``write_csv``
strings these steps together."""
from __future__ import annotations

import numpy as np

from campaign.errors import DataError

from .dataset import ENV_COLUMNS, SCALAR_COLUMNS, Dataset
from .interchange_reader import BAD_ID_CHARS, SMR_COLUMNS, MAX_ID_CHARS, order_columns


def header_columns(ds: Dataset) -> list[str]:
    """Column names present in ``ds``, in the canonical write order."""
    names = ["point_id", "set", *(f"q{k}" for k in range(1, ds.n_joints + 1)), "x", "y", "z"]
    for k in (2, 3):
        if getattr(ds, f"p{k}_tracker_mm") is not None:
            names += SMR_COLUMNS[k]
    names += [s for s in SCALAR_COLUMNS if getattr(ds, s) is not None]
    if ds.qc_deg is not None:
        names += [f"qc{k}" for k in range(1, ds.n_joints + 1)]
    names += [e for e in ENV_COLUMNS if getattr(ds, e) is not None]
    names += order_columns(ds.n_joints) * (ds.order_context is not None)
    return names + ["nest_id"] * (ds.nest_id is not None)


def numeric_block(ds: Dataset) -> np.ndarray:
    """(N, m) float matrix of every numeric column, in header order."""
    parts = [ds.q_deg, ds.p_tracker_mm]
    parts += [a for a in (ds.p2_tracker_mm, ds.p3_tracker_mm) if a is not None]
    parts += [getattr(ds, s)[:, None] for s in SCALAR_COLUMNS if getattr(ds, s) is not None]
    parts += [ds.qc_deg] if ds.qc_deg is not None else []
    parts += [getattr(ds, e)[:, None] for e in ENV_COLUMNS if getattr(ds, e) is not None]
    c = ds.order_context
    if c is not None:
        parts += [c.approach, np.degrees(c.move_rad), np.degrees(c.prev_move_rad), c.order[:, None]]
    return np.hstack(parts)


def blank_allowed(ds: Dataset, names: list[str]) -> np.ndarray:
    """(N, m) bool: numeric cells that may be written empty (NaN): see :func:`_blank_cells`."""
    numeric = [n for n in names if n not in ("point_id", "set", "nest_id")]
    nest = np.array([s == "nest" for s in ds.set])
    on_nest = {f"q{k}" for k in range(1, ds.n_joints + 1)} | {f"qc{k}" for k in range(1, ds.n_joints + 1)}
    on_nest |= set(SMR_COLUMNS[2]) | set(SMR_COLUMNS[3]) | {"temp_c", "payload_kg"}
    anywhere = set(ENV_COLUMNS) | {c for c in order_columns(ds.n_joints) if c.startswith("move")}
    cols = [np.ones(len(ds), bool) if n in anywhere else (nest if n in on_nest else np.zeros(len(ds), bool))
            for n in numeric]
    return np.stack(cols, axis=1)


def check_writable(ds: Dataset, src: str, numbers: np.ndarray, blank_ok: np.ndarray | None = None) -> None:
    """Refuse data that :func:`read_csv` would not read back identically."""
    if len(ds) == 0:
        raise DataError(src, "no data rows to write")
    if ds.p3_tracker_mm is not None and ds.p2_tracker_mm is None:
        raise DataError(src, "p3_tracker_mm needs p2_tracker_mm")
    for i, pid in enumerate(ds.point_id):
        if not pid or pid != pid.strip() or pid.startswith("#") or BAD_ID_CHARS & set(pid) or len(pid) > MAX_ID_CHARS:
            raise DataError(src, f"row {i + 1}: point_id {pid[:40]!r}{'...' * (len(pid) > 40)} cannot be written to CSV")
    for i, nid in enumerate(ds.nest_id or ()):
        if nid != nid.strip() or BAD_ID_CHARS & set(nid):
            raise DataError(src, f"row {i + 1}: nest_id {nid!r} cannot be written to CSV")
    bad = ~np.isfinite(numbers)
    if blank_ok is not None:
        bad &= ~(blank_ok & np.isnan(numbers))
    bad = np.argwhere(bad)
    if bad.size:
        raise DataError(src, f"row {int(bad[0, 0]) + 1}: non-finite value")
