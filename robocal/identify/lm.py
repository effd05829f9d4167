"""One Levenberg-Marquardt loop for every least-squares fit in robocal (geometry, elasto-geometry, multi-SMR)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np


@dataclass(frozen=True)
class Normal:
    """The normal equations of a linearised least-squares problem r ~ A dx: H = A^T A (P, P), g = A^T r (P,), the
    cost r.r and the number of rows m of A; accumulated over row blocks (``+``) when A is never held whole."""
    H: np.ndarray
    g: np.ndarray
    cost: float
    m: int

    @classmethod
    def of(cls, r: np.ndarray, A: np.ndarray) -> "Normal":
        return cls(A.T @ A, A.T @ r, float(r @ r), len(r))

    def __add__(self, other: "Normal") -> "Normal":
        return Normal(self.H + other.H, self.g + other.g, self.cost + other.cost, self.m + other.m)


@dataclass(frozen=True)
class LMResult:
    """``state`` at the solution, the normal equations of its (scaled) linearisation, cost r.r, iterations used."""
    state: Any
    normal: Normal
    cost: float
    iterations: int
    converged: bool


def levenberg_marquardt(state, linearise: Callable[[Any], Normal | tuple[np.ndarray, np.ndarray]],
                        step: Callable[[Any, np.ndarray], tuple[Any, np.ndarray]], ridge_mu: float,
                        max_iter: int, step_tol: float) -> LMResult:
    """Minimise |r|^2 from ``state``: ``linearise(state)`` -> the ``Normal`` equations of r = measured - model
    (whitened) and A its column-scaled Jacobian, or (r, A); ``step(state, dx_scaled) -> (new_state, dx)`` applies a
    step and returns the parameter change that the convergence test ``max|dx| < step_tol`` looks at. Marquardt
    damping on diag(A^T A) plus a ridge ``ridge_mu``; stops on a small step or a relative cost change below 1e-14."""
    def normal(s) -> Normal:
        out = linearise(s)
        return out if isinstance(out, Normal) else Normal.of(*out)

    lam = 1e-3
    ne = normal(state)
    cost = ne.cost
    converged, it = False, 0
    for it in range(1, max_iter + 1):
        H, g = ne.H, ne.g
        eye = np.eye(H.shape[0])
        while True:
            dx_scaled = np.linalg.solve(H + lam * np.diag(np.diag(H)) + ridge_mu * eye, g)
            trial, dx = step(state, dx_scaled)
            ne_t = normal(trial)
            if ne_t.cost <= cost or lam > 1e12:
                break
            lam *= 10.0
        old = cost
        state, ne, cost = trial, ne_t, ne_t.cost
        lam = max(lam / 10.0, 1e-9)
        if np.max(np.abs(dx)) < step_tol or old - cost < 1e-14 * max(old, 1e-300):
            converged = True
            break
    return LMResult(state, ne, cost, it, converged)
