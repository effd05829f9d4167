"""Tracker-registration drift from fixed reference nests: a rigid motion of the tracker frame, smooth in time.

Nest k (fixed on the floor) read at time t in the tracker frame::

    p_k(t) = p_k0 + u(t) . (v + w x p_k0)        u(t) = (tau, tau^2, ..., tau^D),  tau = t / T

with small-angle rotation coefficients w (rad) and translations v (mm) per power of tau, and drift 0 at t = 0
(the start of the run, whose frame the registration then refers to). ``w x p_k0`` is linearised about the
nests' mean readings, so the fit is one linear least-squares problem. The degree D (0 = no drift), and whether
a rotation is part of it, are chosen by leave-one-round-out cross-validation over the nest rounds; rotation is
a candidate only with three or more non-collinear nests. Pure numpy: positions in mm, times in s, no I/O.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.kinematics.frames import skew

MAX_DEGREE = 3
MIN_SPREAD_MM = 50.0      # nests closer than this to a line do not determine a rotation


@dataclass(frozen=True)
class DriftModel:
    """A fitted drift. ``v_mm`` (D, 3) and ``w_rad`` (D, 3) coefficients of tau^1..tau^D; ``t_scale_s`` T;
    ``rotation`` whether w was identified; ``cv_rms_mm`` {"D" or "D+rotation": leave-one-round-out RMS of the
    nest readings};
    ``residual_rms_mm`` RMS of the nest readings after the model; ``nest_ids``, ``p_nest_tracker_mm`` (K, 3)
    the nests' positions at t = 0."""
    v_mm: np.ndarray
    w_rad: np.ndarray
    t_scale_s: float
    rotation: bool
    cv_rms_mm: dict = field(default_factory=dict)
    residual_rms_mm: float = 0.0
    nest_ids: tuple = ()
    p_nest_tracker_mm: np.ndarray | None = None

    @property
    def degree(self) -> int:
        return int(len(self.v_mm))

    def _u(self, t_s: np.ndarray) -> np.ndarray:
        tau = np.asarray(t_s, float) / self.t_scale_s
        return tau[:, None] ** np.arange(1, self.degree + 1)[None, :]

    def translation_mm(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3) translation part of the drift at times t_s (N,)."""
        return self._u(t_s) @ self.v_mm

    def rotation_rad(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3) small-angle rotation vector of the drift at times t_s (N,)."""
        return self._u(t_s) @ self.w_rad

    def displacement_mm(self, p_tracker_mm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """(N, 3) apparent displacement of fixed points read at p_tracker_mm (N, 3) at times t_s (N,)."""
        if self.degree == 0:
            return np.zeros_like(np.asarray(p_tracker_mm, float))
        return self.translation_mm(t_s) + np.cross(self.rotation_rad(t_s), p_tracker_mm)

    def correct(self, p_tracker_mm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """Readings (N, 3) mm taken at t_s moved into the tracker frame of t = 0."""
        p = np.asarray(p_tracker_mm, float)
        return p - self.displacement_mm(p, t_s)

    def to_dict(self) -> dict:
        return {"degree": self.degree, "t_scale_s": self.t_scale_s, "rotation": self.rotation,
                "v_mm": self.v_mm.tolist(), "w_rad": self.w_rad.tolist(),
                "cv_rms_mm": dict(self.cv_rms_mm),
                "residual_rms_mm": self.residual_rms_mm, "nest_ids": list(self.nest_ids)}


def nest_rounds(nest: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Round number of each reading: its occurrence count among readings of the same nest, in time order."""
    order = np.argsort(t_s, kind="stable")
    r = np.zeros(len(nest), int)
    seen: dict[int, int] = {}
    for i in order:
        r[i] = seen.get(int(nest[i]), 0)
        seen[int(nest[i])] = r[i] + 1
    return r


def _design(nest: np.ndarray, tau: np.ndarray, p_mean: np.ndarray, degree: int, rotation: bool) -> np.ndarray:
    """(3M, 3K + degree * (3 or 6)) design matrix: nest positions, then per power v (and w)."""
    m, k = len(nest), len(p_mean)
    cols = np.zeros((m, 3, 3 * k))
    cols[np.arange(m)[:, None], np.arange(3)[None, :], 3 * nest[:, None] + np.arange(3)[None, :]] = 1.0
    blocks = [cols]
    for d in range(1, degree + 1):
        u = (tau**d)[:, None, None]
        blocks.append(u * np.eye(3)[None])
        if rotation:
            blocks.append(-u * skew(p_mean[nest]))
    return np.concatenate(blocks, axis=2).reshape(3 * m, -1)


def _solve(nest, tau, p, p_mean, degree, rotation):
    A = _design(nest, tau, p_mean, degree, rotation)
    x, *_ = np.linalg.lstsq(A, p.reshape(-1), rcond=None)
    return x


def _held_out_rounds(rounds: np.ndarray, nest: np.ndarray, k: int, n_rounds: int) -> np.ndarray:
    """The interior rounds (1 .. n_rounds - 2) that hold readings and leave every nest in the training set."""
    count = np.zeros((max(n_rounds, 1), max(k, 1)), int)
    np.add.at(count, (rounds, nest), 1)
    left = count.sum(axis=0)[None, :] - count
    r = np.arange(1, n_rounds - 1)
    return r[(count[r].sum(axis=1) > 0) & np.all(left[r] > 0, axis=1)]


def _leave_round_out_rms(A: np.ndarray, b: np.ndarray, row_round: np.ndarray, held: np.ndarray) -> float:
    """RMS (3-D, mm) of the readings of every ``held`` round predicted by the least-squares fit of all other rows
    of A x = b: one normal-equation downdate per round (A column-scaled), batched."""
    scale = np.linalg.norm(A, axis=0)
    As = A / np.where(scale > 0, scale, 1.0)
    n_r = int(row_round.max()) + 1
    G_r = np.zeros((n_r, As.shape[1], As.shape[1]))
    np.add.at(G_r, row_round, As[:, :, None] * As[:, None, :])
    h_r = np.zeros((n_r, As.shape[1]))
    np.add.at(h_r, row_round, As * b[:, None])
    x = np.einsum("rij,rj->ri", np.linalg.pinv(G_r.sum(0) - G_r[held]), h_r.sum(0) - h_r[held])   # (H, P)
    slot = np.full(n_r, -1)
    slot[held] = np.arange(len(held))
    rows = slot[row_round] >= 0
    e = b[rows] - np.einsum("ip,ip->i", As[rows], x[slot[row_round[rows]]])
    return float(np.sqrt(np.sum(e**2) / (len(e) / 3)))


def _unpack(x: np.ndarray, k: int, degree: int, rotation: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p0 = x[: 3 * k].reshape(k, 3)
    per = 6 if rotation else 3
    coef = x[3 * k:].reshape(degree, per)
    w = coef[:, 3:] if rotation else np.zeros((degree, 3))
    return p0, coef[:, :3], w


def fit_drift(t_s: np.ndarray, nest: np.ndarray, p_tracker_mm: np.ndarray, nest_ids=(),
              max_degree: int = MAX_DEGREE, rounds: np.ndarray | None = None) -> DriftModel:
    """Drift model from nest readings: times t_s (M,) s, nest index nest (M,) int in 0..K-1, readings
    p_tracker_mm (M, 3) mm. Degree 0..max_degree by leave-one-round-out CV over the interior rounds (robot points
    always lie between the first and the last round, so interpolation is what counts; the lowest CV RMS wins,
    ties to the lower degree); with fewer than 3 rounds the model is degree 0 (no drift). ``rounds`` (M,) the
    round number of each reading when some were set aside (default: counted per nest in time order)."""
    t = np.asarray(t_s, float)
    nest = np.asarray(nest, int)
    p = np.asarray(p_tracker_mm, float)
    k = int(nest.max()) + 1 if len(nest) else 0
    p_mean = np.array([p[nest == j].mean(axis=0) for j in range(k)]) if k else np.zeros((0, 3))
    spread = np.linalg.svd(p_mean - p_mean.mean(axis=0), compute_uv=False) if k >= 3 else np.zeros(1)
    can_rotate = bool(k >= 3 and len(spread) >= 2 and spread[1] > MIN_SPREAD_MM)
    scale = float(max(np.ptp(t), 1.0)) if len(t) else 1.0
    tau = t / scale
    if rounds is None:
        rounds = nest_rounds(nest, t) if len(t) else np.zeros(0, int)
    rounds = np.asarray(rounds, int)
    n_rounds = int(rounds.max()) + 1 if len(rounds) else 0
    top = min(max_degree, n_rounds - 2)
    cv: dict = {}
    candidates = [(d, r) for d in range(0, max(top, 0) + 1) for r in ((False, True) if can_rotate and d else (False,))]
    held = _held_out_rounds(rounds, nest, k, n_rounds)
    for degree, rotation in candidates:
        if len(held):
            A = _design(nest, tau, p_mean, degree, rotation)
            cv[(degree, rotation)] = _leave_round_out_rms(A, p.reshape(-1), np.repeat(rounds, 3), held)
    best = min(cv.values()) if cv else 0.0
    degree, rotation = min((c for c, v in cv.items() if v <= best), default=(0, False))   # ties: simplest
    cv = {f"{d}{'+rotation' if r else ''}": v for (d, r), v in cv.items()}
    if k == 0:
        return DriftModel(np.zeros((0, 3)), np.zeros((0, 3)), scale, False, cv, 0.0, tuple(nest_ids))
    x = _solve(nest, tau, p, p_mean, degree, rotation)
    p0, v, w = _unpack(x, k, degree, rotation)
    u = tau[:, None] ** np.arange(1, degree + 1)[None, :]
    res = p - (p0[nest] + u @ v + np.cross(u @ w, p_mean[nest]))
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return DriftModel(v, w, scale, rotation, cv, rms, tuple(nest_ids), p0)
