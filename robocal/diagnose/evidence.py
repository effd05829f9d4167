"""Evidence on the engine's answer, never a gate: confusable classes (rivals that predicted as well), confounds
with the measurement order, and the consistency of an effect's parameters between near/far reach and the first
and second half of the run. Everything here works on the linearised design of the fit rows (N x P, no N^2)."""
from __future__ import annotations

import math

import numpy as np

from robocal.effects.cv import varies
from robocal.identify.whitened import DesignFactor
from .prose import DRIFT_EXPERIMENT, separating_experiment

DRIFT = "registration_drift"
FACTOR_ROWS = 4096      # fit rows per block of the consistency's triangular factors


def _project_out(X: np.ndarray, G: np.ndarray) -> np.ndarray:
    """X (M, k) minus its least-squares fit by the columns of G (M, g)."""
    if G.shape[1] == 0:
        return X
    nrm = np.linalg.norm(G, axis=0)
    nrm[nrm == 0] = 1.0
    beta = np.linalg.lstsq(G / nrm, X, rcond=1e-10)[0]
    return X - (G / nrm) @ beta


def follows_order(x: np.ndarray, order: np.ndarray, window: int | None = None) -> float:
    """r in [0, 1]: how closely x (N,) or (N, k) follows a smooth function of the measurement order: the share of
    its variance that a running mean over ``window`` neighbours in the order (default N / 20) reproduces, square
    root. Random order gives about 1 / sqrt(window); a sweep that follows the order gives close to 1."""
    x = np.asarray(x, float).reshape(len(x), -1)
    n = len(x)
    w = max(5, n // 20) if window is None else window
    xs = x[np.argsort(np.asarray(order, float), kind="stable")]
    xs = xs - xs.mean(axis=0)
    tot = float(np.sum(xs**2))
    if tot <= 0 or n < 2 * w:
        return 0.0
    c = np.cumsum(np.vstack([np.zeros((1, xs.shape[1])), xs]), axis=0)
    lo = np.clip(np.arange(n) - w // 2, 0, n - w)
    smooth = (c[lo + w] - c[lo]) / w
    return math.sqrt(max(0.0, 1.0 - float(np.sum((xs - smooth) ** 2)) / tot))


def visible(d_mm: np.ndarray, J_geo: np.ndarray) -> np.ndarray:
    """The part of a displacement d (N, 3) mm that the geometry (``J_geo`` (N, 3, P)) cannot absorb."""
    N = len(d_mm)
    return _project_out(d_mm.reshape(-1, 1), J_geo.reshape(3 * N, -1))[:, 0].reshape(N, 3)


def joints_following_order(q_rad: np.ndarray, order: np.ndarray, r_min: float) -> list[tuple[int, float]]:
    """[(joint, r)] of the joints whose angle correlates with the measurement order by |r| > ``r_min``."""
    out = []
    moving = varies(q_rad)
    for j in range(q_rad.shape[1]):
        if moving[j]:
            r = float(np.corrcoef(q_rad[:, j], order)[0, 1])
            if abs(r) > r_min:
                out.append((j + 1, r))
    return out


def confound(name: str, label: str, signal: np.ndarray, q_rad, order, clock: str | None, r_min: float
             ) -> dict | None:
    """The effect and a drift in measurement order as one class when the effect's regressor (``signal``: its joint
    deviations, or its visible displacement) follows the order (r > ``r_min``), or, for the drift itself, when
    joint angles follow the order (then the drift may be those joints' effects). None when the data tell them
    apart."""
    if order is None:
        return None
    if name == DRIFT:
        follow = joints_following_order(q_rad, order, r_min)
        if not follow:
            return None
        js = ", ".join(f"J{j} (r = {r:+.2f})" for j, r in follow)
        return {"class": [label] + [f"effects of J{j} (gear_cyclic J{j}, ...)" for j, _ in follow],
                "joints_following_order": {f"J{j}": r for j, r in follow},
                "text": f"the drift {'in time' if clock == 't_s' else 'in measurement order'} is confounded with "
                        f"effects of {js}: the poses were measured in an order that follows those joints",
                "experiment": DRIFT_EXPERIMENT}
    r = follows_order(signal, order)
    if r <= r_min:
        return None
    return {"class": [label, "drift in measurement order (registration_drift)"], "r_order": r,
            "text": f"{label} follows the measurement order (r = {r:.2f} > {r_min:g}): it and a drift in time are "
                    "one class in these data", "experiment": DRIFT_EXPERIMENT}


def consistency(A_w: np.ndarray, y_w: np.ndarray, cols: np.ndarray, halves: dict[str, np.ndarray],
                geo_cols: np.ndarray) -> tuple[dict, dict]:
    """For each split {name: (M,) bool} of the fit rows: fit the linear model (A_w (M, 3, P) whitened, y_w (M, 3))
    on each half and compare the effect's parameters (``cols``) by the visible displacement of their difference,
    as a share of the effect's own visible displacement (a physical effect has one set of parameters). Returns
    (those shares, the difference in units of what noise alone would give: the residual scatter of the whole
    fit propagated through both halves' fits). Every fit, norm and covariance is that of the triangular factor of
    [A_w y_w] (``_factor``: row blocks, no copy of the design)."""
    M, _, P = A_w.shape
    nrm = np.sqrt(np.einsum("mip,mip->p", A_w, A_w, dtype=float))
    nrm[nrm == 0] = 1.0
    R = _factor(A_w, y_w, nrm)
    full = np.linalg.lstsq(R[:, :P], R[:, P], rcond=1e-10)[0]
    s2 = float(np.sum((R[:, P] - R[:, :P] @ full) ** 2)) / max(3 * M - P, 1)    # |y - A x| = |R_y - R_A x|
    Xv = _project_out(R[:, cols], R[:, geo_cols])          # |Xv x| is the visible displacement of x (A_w = Q R)
    own = float(np.linalg.norm(Xv @ full[cols]))
    XtX = Xv.T @ Xv
    out, noise = {}, {}
    for name, mask in halves.items():
        est, var = [], 0.0
        for half in (mask, ~mask):
            if half.sum() < max(10, P // 3 + 1):
                break
            Rh = _factor(A_w, y_w, nrm, half)
            est.append(np.linalg.lstsq(Rh[:, :P], Rh[:, P], rcond=1e-10)[0][cols])
            C = np.linalg.pinv(Rh[:, :P].T @ Rh[:, :P], rcond=1e-10)[np.ix_(cols, cols)] * s2
            var += float(np.sum(C * XtX))
        if len(est) == 2 and own > 0:
            diff = float(np.linalg.norm(Xv @ (est[0] - est[1])))
            out[name] = diff / own
            noise[name] = diff / math.sqrt(var) if var > 0 else math.inf
    return out, noise


def _factor(A_w: np.ndarray, y_w: np.ndarray, nrm: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """Triangular factor of [A_w / nrm  y_w] (3M rows, P + 1 columns) over the rows ``rows`` (M,) bool (default all),
    gathered over row blocks of ``FACTOR_ROWS``."""
    P = A_w.shape[2]

    def blocks():
        for s in range(0, len(A_w), FACTOR_ROWS):
            b = slice(s, s + FACTOR_ROWS)
            A, y = np.asarray(A_w[b], float) / nrm, y_w[b]
            if rows is not None:
                A, y = A[rows[b]], y[rows[b]]
            if len(A):
                yield np.column_stack([A.reshape(-1, P), y.reshape(-1)])
    return np.linalg.qr(DesignFactor(blocks()).R, mode="r")


def rival_class(step, later=()) -> list[dict]:
    """Rivals of a taken effect with another name that predicted held-out points as well (the winner's paired t
    over them < 2): one confusable class, with the experiment that separates each. A rival that a later step
    (``later``: the steps taken after this one) took, or that rivalled it, belongs to that step: the model holds
    both structures, so the data did tell this effect from it."""
    elsewhere = {s.choice.label for s in later} | {r[0] for s in later for r in s.rivals}
    out = []
    for label, name, rms, t in step.rivals:
        if name == step.choice.name or label in elsewhere:
            continue
        out.append({"effect": name, "label": label, "cv_rms_mm": rms, "t_winner_over_it": t,
                    "experiment": separating_experiment(step.choice.name, name, f"{step.choice.label} {label}")})
    return out
