"""Serial-robot kinematic models: standard DH, modified DH (Craig) and Hayati's beta.

Per joint i (``theta_DH = q_i + theta_i``), the link transform is

* ``dh``  (seed 000 eq. 1): ``Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)``
* ``mdh`` (Craig):          ``Rx(alpha) Ry(beta) Tx(a) Rz(theta) Tz(d)``

``beta`` is Hayati's rotation about y for nearly parallel consecutive axes; it is zero nominally and
identified only on joints flagged ``hayati``. The chain gives ``T_base_flange``; the SMR sits at
``p_flange_smr_mm`` and the base is registered in the tracker frame by ``T_tracker_base``.
All functions are batched over poses: joint angles ``(N, n)`` rad, no Python loop over poses.

A robot on a linear track (``track`` not None): joint 1 is the carriage, a prismatic joint that moves the arm's
base by ``s * track`` (``track``: the displacement per mm of travel in the base frame, the unit axis nominally;
its direction and length are identified, parameters ``track_x, track_y, track_z``). Its DH row is unused (zeros).
The base frame is the arm's base at travel 0. The carriage position is carried in the joint vectors like an angle
so that every degree/radian conversion at the edges stays exact: ``q_deg`` holds it in mm, ``q_rad`` in
``mm * pi / 180`` (``track_mm``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from .frames import exp_se3_left, inv_T, matrix_to_rotvec, transform_points

JOINT_PARAMS = ("theta", "d", "a", "alpha", "beta")
BASE_PARAMS = ("base_tx", "base_ty", "base_tz", "base_rx", "base_ry", "base_rz")
TRACK_PARAMS = ("track_x", "track_y", "track_z")
TOOL_PARAMS = ("tool_x", "tool_y", "tool_z")
JACOBIAN_ROWS = 8192          # poses per block of the identification Jacobian (bounded memory at any N)
CHAIN_ROWS = 4096             # poses per block of the frames-only chain (cache-sized blocks: faster at 10^5 poses)
UNITS = {"theta": "rad", "d": "mm", "a": "mm", "alpha": "rad", "beta": "rad",
         "base_t": "mm", "base_r": "rad", "tool": "mm"}


def _arr(x, n=None) -> np.ndarray:
    a = np.array(x, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Geometry of one robot + its SMR + its registration in the tracker frame.

    Arrays of shape ``(n,)``: ``alpha_rad, a_mm, d_mm, theta_rad, beta_rad, q_min_rad, q_max_rad``.
    ``T_tracker_base`` (4, 4) mm; ``p_flange_smr_mm`` (3,) mm.
    """
    convention: str
    alpha_rad: np.ndarray
    a_mm: np.ndarray
    d_mm: np.ndarray
    theta_rad: np.ndarray
    beta_rad: np.ndarray
    q_min_rad: np.ndarray
    q_max_rad: np.ndarray
    hayati: tuple[bool, ...]
    T_tracker_base: np.ndarray = field(default_factory=lambda: np.eye(4))
    p_flange_smr_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    track: np.ndarray | None = None

    def __post_init__(self):
        if self.convention not in ("dh", "mdh"):
            raise ValueError(f"unknown convention {self.convention!r}")
        for name in ("alpha_rad", "a_mm", "d_mm", "theta_rad", "beta_rad", "q_min_rad", "q_max_rad",
                     "T_tracker_base", "p_flange_smr_mm"):
            object.__setattr__(self, name, _arr(getattr(self, name)))
        if self.track is not None:
            object.__setattr__(self, "track", _arr(self.track))
            if self.track.shape != (3,) or not np.linalg.norm(self.track) > 0:
                raise ValueError("track: the carriage displacement per mm of travel, 3 numbers, not zero")
        n = len(self.a_mm)
        if any(len(getattr(self, k)) != n for k in ("alpha_rad", "d_mm", "theta_rad", "beta_rad")):
            raise ValueError("DH arrays must all have the number of joints")
        if len(self.hayati) != n:
            raise ValueError("hayati flags must have one entry per joint")

    @property
    def n(self) -> int:
        return len(self.a_mm)

    @property
    def n_track(self) -> int:
        """1 when joint 1 is a linear track, else 0 (the index of the arm's first joint)."""
        return 0 if self.track is None else 1

    def arm(self) -> "Kinematics":
        """The arm without its track (the carriage at travel 0); the chain itself when it has none."""
        if self.track is None:
            return self
        cut = lambda a: a[1:]                                           # noqa: E731
        return replace(self, alpha_rad=cut(self.alpha_rad), a_mm=cut(self.a_mm), d_mm=cut(self.d_mm),
                       theta_rad=cut(self.theta_rad), beta_rad=cut(self.beta_rad), q_min_rad=cut(self.q_min_rad),
                       q_max_rad=cut(self.q_max_rad), hayati=self.hayati[1:], track=None)

    def with_(self, **changes) -> "Kinematics":
        """Copy with fields replaced."""
        return replace(self, **changes)

    @classmethod
    def from_table(cls, convention: str, alpha_deg, a_mm, d_mm, theta_deg, q_min_deg, q_max_deg,
                   hayati_joints=(), T_tracker_base=None, p_flange_smr_mm=(0, 0, 0), track_axis=None) -> "Kinematics":
        """Build from a DH table in degrees/mm (the form of configs and papers). ``hayati_joints``: 1-based joints
        whose axis is parallel to the next one; beta goes on the row of the transform between the two axes,
        ``hayati_row``. ``track_axis`` (3,): joint 1 is a linear track along it (its row's DH values are ignored;
        its limits in mm)."""
        n = len(a_mm)
        rows = {hayati_row(convention, j) for j in hayati_joints}
        track = None if track_axis is None else np.asarray(track_axis, float) / np.linalg.norm(track_axis)
        zero = lambda v: np.r_[0.0, np.asarray(v, float)[1:]] if track is not None else v      # noqa: E731
        return cls(convention, np.radians(zero(alpha_deg)), zero(a_mm), zero(d_mm), np.radians(zero(theta_deg)),
                   np.zeros(n), np.radians(q_min_deg), np.radians(q_max_deg),
                   tuple(i in rows for i in range(n)),
                   np.eye(4) if T_tracker_base is None else T_tracker_base, p_flange_smr_mm, track)

    def to_dict(self) -> dict:
        """Plain dict with units in the keys (angles in degrees for readability)."""
        return {
            "convention": self.convention,
            "alpha_deg": np.degrees(self.alpha_rad).tolist(), "a_mm": self.a_mm.tolist(),
            "d_mm": self.d_mm.tolist(), "theta_deg": np.degrees(self.theta_rad).tolist(),
            "beta_deg": np.degrees(self.beta_rad).tolist(),
            "q_min_deg": np.degrees(self.q_min_rad).tolist(), "q_max_deg": np.degrees(self.q_max_rad).tolist(),
            "hayati": list(self.hayati), "T_tracker_base": self.T_tracker_base.tolist(),
            "p_flange_smr_mm": self.p_flange_smr_mm.tolist(),
        } | ({} if self.track is None else {"track": self.track.tolist()})

    @classmethod
    def from_dict(cls, d: dict) -> "Kinematics":
        return cls(d["convention"], np.radians(d["alpha_deg"]), d["a_mm"], d["d_mm"], np.radians(d["theta_deg"]),
                   np.radians(d["beta_deg"]), np.radians(d["q_min_deg"]), np.radians(d["q_max_deg"]),
                   tuple(bool(h) for h in d["hayati"]), np.array(d["T_tracker_base"]), d["p_flange_smr_mm"],
                   None if d.get("track") is None else np.array(d["track"], float))


def hayati_row(convention: str, joint: int) -> int:
    """0-based row that holds Hayati's beta for the parallel pair (joint, joint + 1) (1-based joint): the row of
    the transform from axis ``joint`` to axis ``joint + 1``, row ``joint`` in standard DH (``Rz Tz Tx Rx Ry``),
    row ``joint + 1`` in modified DH (``Rx Ry Tx Rz Tz``, where alpha_i and a_i of that pair live)."""
    return joint - 1 if convention == "dh" else joint


class Chain(NamedTuple):
    """Intermediate frames of a batch of poses, all in the base frame.

    ``T_base_flange`` (N, 4, 4). Per joint i, ``axis[:, i]``/``origin[:, i]`` give the joint's rotation axis
    and a point on it, and ``dirs[k][i]``/``pts[k][i]`` (N, 3) the direction and pivot of each parameter's
    elementary motion (k indexes JOINT_PARAMS; tuples of the frames' own arrays, shared, never copied); pivots are
    unused for the prismatic ones (d, a).
    """
    T_base_flange: np.ndarray
    axis: np.ndarray
    origin: np.ndarray
    dirs: tuple | None
    pts: tuple | None


def _per_pose(x: np.ndarray, i: int) -> np.ndarray:
    """Parameter i of an array that is (n,) or per pose (N, n)."""
    return x[..., i]


def _col(x):
    """Per-pose scalar as a column (N, 1) (or (1, 1) when shared) for broadcasting against (N, 3)."""
    return np.reshape(x, (-1, 1))


def chain(kin: Kinematics, q_rad: np.ndarray, *, alpha=None, a=None, d=None, theta=None, beta=None,
          full: bool = True, axes: bool = True) -> Chain:
    """Forward kinematics with all intermediate frames. q_rad (N, n). Optional per-pose (N, n) overrides
    of the DH arrays (used by effect models such as thermal growth). ``full=False`` skips the per-parameter
    directions (``dirs``/``pts`` are then None), which IK does not need.

    Frames are propagated as their axis columns x, y, z and origin o (N, 3): every elementary rotation
    is two vector combinations, far cheaper than batched 4x4 products."""
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    N, n = q.shape
    if n != kin.n:
        raise ValueError(f"expected {kin.n} joint values per pose, got {n}")
    alpha = kin.alpha_rad if alpha is None else alpha
    a = kin.a_mm if a is None else a
    d = kin.d_mm if d is None else d
    theta = kin.theta_rad if theta is None else theta
    beta = kin.beta_rad if beta is None else beta
    if not full and N > CHAIN_ROWS:
        return _chain_blocks(kin, q, dict(alpha=alpha, a=a, d=d, theta=theta, beta=beta), axes)
    o = np.zeros((N, 3))
    x, y, z = list(np.broadcast_to(np.eye(3), (N, 3, 3)).transpose(1, 0, 2))
    axis = np.empty((N, n, 3)); origin = np.empty((N, n, 3))
    dirs, pts = [[] for _ in range(5)], [[] for _ in range(5)]
    if kin.track is not None:                              # the carriage: a translation along the track
        o = track_mm(q[:, 0])[:, None] * kin.track
        axis[:, 0], origin[:, 0] = kin.track / np.linalg.norm(kin.track), 0.0
        if full:
            _append(dirs, (np.zeros((N, 3)),) * 5)
            _append(pts, (np.zeros((N, 3)),) * 5)
    for i in range(kin.n_track, n):
        th = q[:, i] + _per_pose(theta, i)
        ct, st = np.cos(th)[:, None], np.sin(th)[:, None]
        ca, sa = np.cos(_col(_per_pose(alpha, i))), np.sin(_col(_per_pose(alpha, i)))
        cb, sb = np.cos(_col(_per_pose(beta, i))), np.sin(_col(_per_pose(beta, i)))
        a_i, d_i = _col(_per_pose(a, i)), _col(_per_pose(d, i))
        if kin.convention == "dh":                         # Rz(th) Tz(d) Tx(a) Rx(alpha) Ry(beta)
            oF, zF = o, z
            x1, y1 = ct * x + st * y, ct * y - st * x
            o1 = o + d_i * z
            o2 = o1 + a_i * x1
            y2, z2 = ca * y1 + sa * z, ca * z - sa * y1
            x, y, z, o = cb * x1 - sb * z2, y2, sb * x1 + cb * z2, o2
            axis[:, i], origin[:, i] = zF, oF
            if full:
                _append(dirs, (zF, zF, x1, x1, y2))
                _append(pts, (oF, oF, oF, o2, o2))
        else:                                              # Rx(alpha) Ry(beta) Tx(a) Rz(th) Tz(d)
            oF, xF = o, x
            y1, z1 = ca * y + sa * z, ca * z - sa * y
            x2, z2 = cb * x - sb * z1, sb * x + cb * z1
            o2 = o + a_i * x2
            x, y, z, o = ct * x2 + st * y1, ct * y1 - st * x2, z2, o2 + d_i * z2
            axis[:, i], origin[:, i] = z2, o2
            if full:
                _append(dirs, (z2, z2, x2, xF, y1))
                _append(pts, (o2, o2, o2, oF, oF))
    T = np.zeros((N, 4, 4))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3], T[:, 3, 3] = x, y, z, o, 1.0
    if not full:
        return Chain(T, axis, origin, None, None)
    return Chain(T, axis, origin, tuple(map(tuple, dirs)), tuple(map(tuple, pts)))


def track_mm(q_rad_track: np.ndarray) -> np.ndarray:
    """The carriage position (mm) of a track joint's value as robocal carries it (mm * pi / 180)."""
    return np.degrees(q_rad_track)


def _chain_blocks(kin: Kinematics, q: np.ndarray, dh: dict, axes: bool = True) -> Chain:
    """``chain(full=False)`` in row blocks of ``CHAIN_ROWS`` poses (per-pose (N, n) DH overrides sliced along):
    the same numbers, computed in cache; ``axes`` False keeps the flange poses only (axis, origin None)."""
    N = len(q)
    T = np.empty((N, 4, 4))
    axis, origin = (np.empty((N, kin.n, 3)), np.empty((N, kin.n, 3))) if axes else (None, None)
    for s in range(0, N, CHAIN_ROWS):
        b = slice(s, s + CHAIN_ROWS)
        c = chain(kin, q[b], full=False, **{k: v[b] if np.ndim(v) == 2 else v for k, v in dh.items()})
        T[b] = c.T_base_flange
        if axes:
            axis[b], origin[b] = c.axis, c.origin
    return Chain(T, axis, origin, None, None)


def _append(lists: list, arrays: tuple) -> None:
    for lst, arr in zip(lists, arrays):
        lst.append(arr)


def fk(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """T_base_flange (N, 4, 4) for joint angles (N, n) rad."""
    return chain(kin, q_rad, full=False, axes=False).T_base_flange


def smr_base(kin: Kinematics, q_rad: np.ndarray, T_base_flange: np.ndarray | None = None) -> np.ndarray:
    """SMR centre in the robot base frame, (N, 3) mm."""
    T = fk(kin, q_rad) if T_base_flange is None else T_base_flange
    return transform_points(T, kin.p_flange_smr_mm)


def smr_tracker(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """SMR centre in the tracker frame, (N, 3) mm."""
    return transform_points(kin.T_tracker_base, smr_base(kin, q_rad))


def joint_jacobian(kin: Kinematics, q_rad: np.ndarray, p_flange_point_mm=None) -> tuple[np.ndarray, np.ndarray]:
    """Geometric Jacobian in the base frame of a point fixed to the flange (default: the SMR).

    Returns (T_base_flange (N, 4, 4), J (N, 6, n)) with rows (v_x, v_y, v_z in mm/rad, w_x, w_y, w_z).
    """
    c = chain(kin, q_rad, full=False)
    pf = kin.p_flange_smr_mm if p_flange_point_mm is None else np.asarray(p_flange_point_mm, float)
    p = transform_points(c.T_base_flange, pf)
    return c.T_base_flange, motion_columns(kin, c, p)


def motion_columns(kin: Kinematics, c: Chain, p_base_mm: np.ndarray) -> np.ndarray:
    """(N, 6, n) velocity of the point p_base_mm (N, 3) (mm per unit joint value) and angular velocity of the
    flange per joint: a revolute joint turns about its axis, a track translates the arm (per mm * pi / 180)."""
    v = np.cross(c.axis, p_base_mm[:, None, :] - c.origin)
    w = c.axis.copy()
    if kin.track is not None:
        v[:, 0], w[:, 0] = np.degrees(kin.track), 0.0
    return np.concatenate([np.swapaxes(v, 1, 2), np.swapaxes(w, 1, 2)], axis=1)


# ---------------------------------------------------------------- parameters
@dataclass(frozen=True)
class ParamLayout:
    """Names of the full candidate parameter vector of a model, in Jacobian column order.

    Per joint: theta, d, a, alpha (+ beta on Hayati joints); a track instead: its displacement per mm of travel
    (``TRACK_PARAMS``, base frame, mm/mm); then base (6, left perturbation in the tracker frame: translation mm,
    rotation rad) and tool (3, mm in the flange frame).
    """
    names: tuple[str, ...]
    joint_cols: tuple[tuple[int, int, int], ...]  # (column, joint index, JOINT_PARAMS index)

    @classmethod
    def of(cls, kin: Kinematics) -> "ParamLayout":
        names, cols = [], []
        for i in range(kin.n_track, kin.n):
            for k, kind in enumerate(JOINT_PARAMS):
                if kind == "beta" and not kin.hayati[i]:
                    continue
                cols.append((len(names), i, k))
                names.append(f"{kind}{i + 1}")
        track = list(TRACK_PARAMS) if kin.track is not None else []
        return cls(tuple(names + track + list(BASE_PARAMS) + list(TOOL_PARAMS)), tuple(cols))

    @property
    def n_joint(self) -> int:
        """Columns before the base: the joints' parameters and the track's."""
        return self.size - len(BASE_PARAMS) - len(TOOL_PARAMS)

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def unit(self, name: str) -> str:
        if name.startswith("base_"):
            return UNITS["base_t"] if name[5] == "t" else UNITS["base_r"]
        if name.startswith("tool_"):
            return UNITS["tool"]
        if name.startswith("track_"):
            return "mm/mm"
        return UNITS[name.rstrip("0123456789")]


def identification_jacobian(kin: Kinematics, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic d p_tracker / d params for all candidate parameters (ParamLayout order).

    Returns (p_tracker_mm (N, 3), J (N, 3, P)). Units per column: mm/rad or mm/mm.
    """
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    if len(q) <= JACOBIAN_ROWS:
        p_tracker, Jt = _jacobian_block(kin, ParamLayout.of(kin), q)
        return p_tracker, np.ascontiguousarray(Jt.transpose(1, 2, 0))
    layout = ParamLayout.of(kin)
    p_tracker, J = np.empty((len(q), 3)), np.empty((len(q), 3, layout.size))
    for s in range(0, len(q), JACOBIAN_ROWS):              # row blocks: the chain's frames for one block at a time
        p_tracker[s:s + JACOBIAN_ROWS], Jt = _jacobian_block(kin, layout, q[s:s + JACOBIAN_ROWS])
        J[s:s + JACOBIAN_ROWS] = Jt.transpose(1, 2, 0)
    return p_tracker, J


def identification_jacobian_t(kin: Kinematics, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``identification_jacobian`` stored by parameter: (p_tracker_mm (N, 3), Jt (P, N, 3)), Jt[c] the (N, 3)
    column c. Every column is written contiguously (the (N, 3, P) layout writes one cache line per value, the
    cost at 10^5 poses); the fitting loops use this form. Computed in row blocks of ``JACOBIAN_ROWS`` poses (the
    chain's intermediate frames of one block at a time: memory bounded at any N, the same numbers)."""
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    layout = ParamLayout.of(kin)
    if len(q) <= JACOBIAN_ROWS:
        return _jacobian_block(kin, layout, q)
    p_tracker, Jt = np.empty((len(q), 3)), np.empty((layout.size, len(q), 3))
    for s in range(0, len(q), JACOBIAN_ROWS):
        p_tracker[s:s + JACOBIAN_ROWS], Jt[:, s:s + JACOBIAN_ROWS] = _jacobian_block(kin, layout, q[s:s + JACOBIAN_ROWS])
    return p_tracker, Jt


def jacobian_blocks(kin: Kinematics, q_rad: np.ndarray, rows: int):
    """``identification_jacobian_t`` of consecutive row blocks of ``rows`` poses: (rows slice, p_tracker_mm (b, 3),
    Jt (P, b, 3)), one block at a time (the fits that accumulate their normal equations never hold all rows' Jacobian)."""
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    layout = ParamLayout.of(kin)
    for s in range(0, len(q), rows):
        b = slice(s, min(s + rows, len(q)))
        yield (b, *_jacobian_block(kin, layout, q[b]))


def _jacobian_block(kin: Kinematics, layout: ParamLayout, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p_tracker_mm (N, 3), Jt (P, N, 3)) of one block of poses."""
    c = chain(kin, q_rad)
    N = c.T_base_flange.shape[0]
    p_base = transform_points(c.T_base_flange, kin.p_flange_smr_mm)
    R_tb = kin.T_tracker_base[:3, :3]
    p_tracker = p_base @ R_tb.T + kin.T_tracker_base[:3, 3]
    Jt = np.empty((layout.size, N, 3))
    prismatic = (1, 2)  # d, a
    w = np.empty((N, 3))
    for col, i, k in layout.joint_cols:                          # base-frame motion, rotated into the tracker frame
        u = c.dirs[k][i] if k in prismatic else _cross(c.dirs[k][i], p_base - c.pts[k][i], w)
        np.matmul(u, R_tb.T, out=Jt[col])
    nj = layout.n_joint
    if kin.track is not None:                                     # s * track: the travel along each base axis
        s = track_mm(np.atleast_2d(q_rad)[:, 0])
        Jt[nj - 3:nj] = s[None, :, None] * R_tb.T[:, None, :]
    Jt[nj:nj + 3] = 0.0
    for a in range(3):
        Jt[nj + a, :, a] = 1.0                                        # base translation
        _cross(np.eye(3)[a][None, :], p_tracker, Jt[nj + 3 + a])      # base rotation about tracker axis a
        Jt[nj + 6 + a] = c.T_base_flange[:, :3, a] @ R_tb.T           # tool offset along flange axis a
    return p_tracker, Jt


def joint_motion_columns(kin: Kinematics, J: np.ndarray) -> np.ndarray:
    """(N, 3, n) d p_tracker / d q_j (mm per unit joint value) from the identification Jacobian J (N, 3, P): each
    revolute joint's theta column; a track's travel (its direction, per mm * pi / 180)."""
    theta = [c for c, _, k in ParamLayout.of(kin).joint_cols if k == 0]
    cols = J[:, :, theta]
    if kin.track is None:
        return cols
    move = np.degrees(kin.T_tracker_base[:3, :3] @ kin.track)
    return np.concatenate([np.broadcast_to(move[None, :, None], (len(J), 3, 1)), cols], axis=2)


def _cross(u: np.ndarray, v: np.ndarray, out: np.ndarray) -> np.ndarray:
    """u x v of (N, 3) (or broadcastable) arrays into ``out`` (N, 3), component-wise (np.cross is slow)."""
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def apply_update(kin: Kinematics, delta: np.ndarray) -> Kinematics:
    """Apply a step over the full candidate vector (ParamLayout order): additive on DH and tool,
    left-multiplicative on the base (T_tracker_base <- Exp(delta_base) @ T_tracker_base)."""
    layout = ParamLayout.of(kin)
    delta = np.asarray(delta, dtype=float)
    arrays = [kin.theta_rad.copy(), kin.d_mm.copy(), kin.a_mm.copy(), kin.alpha_rad.copy(), kin.beta_rad.copy()]
    for col, i, k in layout.joint_cols:
        arrays[k][i] += delta[col]
    nj = layout.n_joint
    track = None if kin.track is None else kin.track + delta[nj - 3:nj]
    return kin.with_(theta_rad=arrays[0], d_mm=arrays[1], a_mm=arrays[2], alpha_rad=arrays[3], beta_rad=arrays[4],
                     T_tracker_base=exp_se3_left(delta[nj:nj + 6], kin.T_tracker_base),
                     p_flange_smr_mm=kin.p_flange_smr_mm + delta[nj + 6:nj + 9], track=track)


def parameter_difference(kin: Kinematics, ref: Kinematics) -> np.ndarray:
    """kin - ref over the full candidate vector (base as a rotation vector of T_kin @ T_ref^-1)."""
    layout = ParamLayout.of(kin)
    out = np.zeros(layout.size)
    pairs = [(kin.theta_rad, ref.theta_rad), (kin.d_mm, ref.d_mm), (kin.a_mm, ref.a_mm),
             (kin.alpha_rad, ref.alpha_rad), (kin.beta_rad, ref.beta_rad)]
    for col, i, k in layout.joint_cols:
        out[col] = pairs[k][0][i] - pairs[k][1][i]
    nj = layout.n_joint
    if kin.track is not None:
        out[nj - 3:nj] = kin.track - ref.track
    D = kin.T_tracker_base @ inv_T(ref.T_tracker_base)
    out[nj:nj + 3] = D[:3, 3]
    out[nj + 3:nj + 6] = matrix_to_rotvec(D[:3, :3])
    out[nj + 6:] = kin.p_flange_smr_mm - ref.p_flange_smr_mm
    return out


def within_limits(kin: Kinematics, q_rad: np.ndarray, margin_rad: float = 0.0) -> np.ndarray:
    """(N,) bool: every joint inside [q_min + margin, q_max - margin]."""
    q = np.atleast_2d(q_rad)
    return np.all((q >= kin.q_min_rad + margin_rad) & (q <= kin.q_max_rad - margin_rad), axis=1)
