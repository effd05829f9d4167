"""One Levenberg-Marquardt loop for every least-squares fit in robocal (geometry, elasto-geometry, multi-SMR)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np


@dataclass(frozen=True)
class LMResult:
    """``state`` at the solution, its residual r (m,) and scaled Jacobian A (m, P), cost r.r, iterations used."""
    state: Any
    r: np.ndarray
    A: np.ndarray
    cost: float
    iterations: int
    converged: bool


def levenberg_marquardt(state, linearise: Callable[[Any], tuple[np.ndarray, np.ndarray]],
                        step: Callable[[Any, np.ndarray], tuple[Any, np.ndarray]], ridge_mu: float,
                        max_iter: int, step_tol: float) -> LMResult:
    """Minimise |r|^2 from ``state``: ``linearise(state) -> (r, A)`` with r = measured - model (whitened) and A its
    column-scaled Jacobian; ``step(state, dx_scaled) -> (new_state, dx)`` applies a step and returns the parameter
    change that the convergence test ``max|dx| < step_tol`` looks at. Marquardt damping on diag(A^T A) plus a
    ridge ``ridge_mu``; stops on a small step or a relative cost change below 1e-14."""
    lam = 1e-3
    r, A = linearise(state)
    cost = float(r @ r)
    converged, it = False, 0
    for it in range(1, max_iter + 1):
        H, g = A.T @ A, A.T @ r
        eye = np.eye(H.shape[0])
        while True:
            dx_scaled = np.linalg.solve(H + lam * np.diag(np.diag(H)) + ridge_mu * eye, g)
            trial, dx = step(state, dx_scaled)
            r_t, A_t = linearise(trial)
            if r_t @ r_t <= cost or lam > 1e12:
                break
            lam *= 10.0
        old = cost
        state, r, A, cost = trial, r_t, A_t, float(r_t @ r_t)
        lam = max(lam / 10.0, 1e-9)
        if np.max(np.abs(dx)) < step_tol or old - cost < 1e-14 * max(old, 1e-300):
            converged = True
            break
    return LMResult(state, r, A, cost, it, converged)
