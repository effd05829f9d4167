"""The measured points of a campaign in memory: :class:`Dataset` (what the CSV, the log and processing share)."""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Callable, Sequence

import numpy as np

from campaign.errors import DataError
from campaign.run.log_records import SETS
from robocal.measure.approach import approach_signs, moves_from_order

SCALAR_COLUMNS = ("t_s", "temp_c", "payload_kg")  # optional per-row scalars, in write order
ENV_COLUMNS = ("env_temp_c", "env_pressure_hpa", "env_humidity_pct")  # optional, empty cell = not read (NaN)


def _frozen(value: Any) -> bool:
    """A float64 array nothing can write to (read-only, over read-only memory): shared, not copied."""
    return (isinstance(value, np.ndarray) and value.dtype == np.float64 and not value.flags.writeable
            and (value.base is None or not getattr(value.base, "flags", value.flags).writeable))


def _float_array(value: Any, name: str, shape: tuple) -> np.ndarray:
    """Read-only float64 copy of ``value`` checked against ``shape`` (-1 = any); another dataset's read-only array is
    shared (a dataset derived from another holds no second copy of what it did not change)."""
    arr = value if _frozen(value) else np.array(value, dtype=np.float64)
    ok = arr.ndim == len(shape) and all(s in (-1, a) for s, a in zip(shape, arr.shape))
    if not ok:
        raise ValueError(f"Dataset.{name}: expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class OrderContext:
    """What the full measurement order gives each row, kept when rows are left out (a subset of a campaign still
    carries how the robot reached each of its poses): approach signs (N, n) -1/0/+1, the signed last move and the
    move before (N, n) rad (NaN next to a row without joints), the row's position in the order (N,)."""
    approach: np.ndarray
    move_rad: np.ndarray
    prev_move_rad: np.ndarray
    order: np.ndarray

    @classmethod
    def of(cls, q_deg: np.ndarray) -> "OrderContext":
        """From all rows' joints (N, n) deg in measurement order (``robocal.measure.approach``)."""
        q = np.radians(np.asarray(q_deg, float))
        move, prev = moves_from_order(q)
        return cls(approach_signs(q), move, prev, np.arange(len(q), dtype=float))

    def take(self, rows: np.ndarray) -> "OrderContext":
        return OrderContext(self.approach[rows], self.move_rad[rows], self.prev_move_rad[rows], self.order[rows])


@dataclass(frozen=True, eq=False)
class Dataset:
    """Measured points, in measurement order (N rows, n joints).

    ``q_deg`` (N, n) joint values in degrees; ``p_tracker_mm`` (N, 3) SMR
    centre in mm, tracker frame; ``p2_tracker_mm``/``p3_tracker_mm`` (N, 3) or
    None; ``t_s`` (N,) seconds, ``temp_c`` (N,) deg C, ``payload_kg`` (N,) kg,
    ``sigma_mm`` (N,) mm (1-sigma, from logs only), each or None.  ``source``
    names where the data came from.  Arrays are read-only float64 copies.
    ``qc_deg`` (N, n) commanded joints in degrees (``q_deg`` then holds the
    read-back ones) or None; ``nest_id`` (N,) text, "" on rows that are not
    ``nest`` rows (reference-nest readings, whose joints are NaN), or None
    without nest rows; ``env_temp_c`` (deg C), ``env_pressure_hpa`` (hPa),
    ``env_humidity_pct`` (%) (N,) tracker weather readings (NaN = not read).
    """

    point_id: tuple[str, ...]
    set: tuple[str, ...]
    q_deg: np.ndarray
    p_tracker_mm: np.ndarray
    t_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    p2_tracker_mm: np.ndarray | None = None
    p3_tracker_mm: np.ndarray | None = None
    sigma_mm: np.ndarray | None = None
    source: str = ""
    qc_deg: np.ndarray | None = None
    nest_id: tuple[str, ...] | None = None
    env_temp_c: np.ndarray | None = None
    env_pressure_hpa: np.ndarray | None = None
    env_humidity_pct: np.ndarray | None = None
    cov_mm2: np.ndarray | None = None  # (N, 3, 3) mm^2 from the tracker's own statistics (logs only), or None
    order_context: OrderContext | None = None  # a subset's rows' places in the order they were measured in
    provenance: str = ""        # how the rows reached this dataset ("imported from FILE (campaign import ...)"), or ""

    def __post_init__(self) -> None:
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        put("point_id", tuple(str(p) for p in self.point_id))
        put("set", tuple(str(s) for s in self.set))
        n_rows = len(self.point_id)
        if len(self.set) != n_rows:
            raise ValueError(f"Dataset.set: expected {n_rows} entries, got {len(self.set)}")
        bad = sorted(set(self.set) - set(SETS))  # builtin set: the field is not in scope here
        if bad:
            raise ValueError(f"Dataset.set: unknown set name(s) {bad}, expected {SETS}")
        put("q_deg", _float_array(self.q_deg, "q_deg", (n_rows, -1)))
        if self.q_deg.shape[1] < 1:
            raise ValueError("Dataset.q_deg: needs at least one joint column")
        put("p_tracker_mm", _float_array(self.p_tracker_mm, "p_tracker_mm", (n_rows, 3)))
        for name in ("p2_tracker_mm", "p3_tracker_mm"):
            if getattr(self, name) is not None:
                put(name, _float_array(getattr(self, name), name, (n_rows, 3)))
        for name in (*SCALAR_COLUMNS, "sigma_mm", *ENV_COLUMNS):
            if getattr(self, name) is not None:
                put(name, _float_array(getattr(self, name), name, (n_rows,)))
        if self.cov_mm2 is not None:
            put("cov_mm2", _float_array(self.cov_mm2, "cov_mm2", (n_rows, 3, 3)))
        if self.qc_deg is not None:
            put("qc_deg", _float_array(self.qc_deg, "qc_deg", self.q_deg.shape))
        if self.order_context is not None:
            c = self.order_context
            put("order_context", OrderContext(*(_float_array(getattr(c, k), f"order_context.{k}", shape) for k, shape in
                                                (("approach", self.q_deg.shape), ("move_rad", self.q_deg.shape),
                                                 ("prev_move_rad", self.q_deg.shape), ("order", (n_rows,))))))
        self._check_nests(put)

    def _check_nests(self, put: Callable[[str, Any], None]) -> None:
        """``nest_id``: one text per row, non-empty exactly on ``nest`` rows."""
        is_nest = [s == "nest" for s in self.set]
        if self.nest_id is None:
            if any(is_nest):
                raise ValueError("Dataset.nest_id: nest rows need a nest_id")
            return
        put("nest_id", tuple(str(v) for v in self.nest_id))
        if len(self.nest_id) != len(self.set):
            raise ValueError(f"Dataset.nest_id: expected {len(self.set)} entries, got {len(self.nest_id)}")
        for i, (nid, nest) in enumerate(zip(self.nest_id, is_nest)):
            if bool(nid) != nest:
                what = "a nest row without nest_id" if nest else f"nest_id {nid!r} on a {self.set[i]} row"
                raise ValueError(f"Dataset.nest_id: row {i + 1}: {what}")

    def __len__(self) -> int:
        return len(self.point_id)

    @property
    def n_joints(self) -> int:
        """Number of joint columns n."""
        return int(self.q_deg.shape[1])

    def require_joints(self, n: int) -> None:
        """DataError unless the data has ``n`` joint columns (those of the config's robot)."""
        if self.n_joints != n:
            raise DataError(self.source, f"has {self.n_joints} joint columns but the config's robot has {n} joints")

    def mask(self, set_name: str) -> np.ndarray:
        """Boolean (N,) array: rows whose ``set`` is ``set_name``."""
        if set_name not in SETS:
            raise ValueError(f"set_name must be one of {SETS}, got {set_name!r}")
        return np.asarray(self.set, dtype=str) == set_name if len(self) else np.zeros(0, bool)

    def subset(self, mask: Sequence[bool] | np.ndarray) -> "Dataset":
        """Rows selected by a boolean (N,) mask or an integer index array.

        Row order is kept, and the ``order_context`` when there is one (see :meth:`with_order_context`: a subset
        that must keep how the robot reached its poses).  Note that :meth:`approach_sign` of a subset only sees the
        subset's rows: compute it on the full dataset and index it.
        """
        sel = np.asarray(mask)
        if sel.dtype == bool:
            if sel.shape != (len(self),):
                raise ValueError(f"mask: expected shape ({len(self)},), got {sel.shape}")
            sel = np.flatnonzero(sel)
        sel = sel.astype(np.intp, copy=False).reshape(-1)
        kwargs: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "order_context":
                kwargs[f.name] = None if value is None else value.take(sel)
            elif f.name in ("point_id", "set") or (f.name == "nest_id" and value is not None):
                kwargs[f.name] = tuple(value[i] for i in sel)
            elif isinstance(value, np.ndarray):
                kwargs[f.name] = value[sel]
            else:
                kwargs[f.name] = value
        return Dataset(**kwargs)

    def with_order_context(self) -> "Dataset":
        """This dataset carrying every row's place in its measurement order (:class:`OrderContext`), so that a
        :meth:`subset` keeps it: computed over the rows with joints, as the calibration does once the nest readings
        are set aside (a nest row gets approach 0, unknown moves and the place of the robot row before it)."""
        if self.order_context is not None:
            return self
        robot = np.all(np.isfinite(self.q_deg), axis=1)
        ctx = OrderContext.of(self.q_deg[robot])
        approach, move, prev = np.zeros(self.q_deg.shape), np.full(self.q_deg.shape, np.nan), np.full(self.q_deg.shape,
                                                                                                          np.nan)
        approach[robot], move[robot], prev[robot] = ctx.approach, ctx.move_rad, ctx.prev_move_rad
        order = np.maximum(np.cumsum(robot) - 1, 0).astype(float)
        return replace(self, order_context=OrderContext(approach, move, prev, order))

    def approach_sign(self, tol_deg: float = 0.0) -> np.ndarray:
        """(N, n) float array of -1/0/+1: direction each joint last moved in.

        Row i holds ``sign(q[i] - q[i-1])`` per joint, from row order; a joint
        that did not move (``|dq| <= tol_deg``) keeps the previous row's sign;
        row 0, and a joint that has not moved yet, is 0.  Rows without joints
        (nest rows, NaN) are skipped and get 0.
        """
        robot = np.all(np.isfinite(self.q_deg), axis=1)
        out = np.zeros(self.q_deg.shape)
        out[robot] = approach_signs(self.q_deg[robot], tol_deg)
        return out
