"""Approach direction: the sign of each joint's last motion before a stop (backlash and read-back lag need it)."""
from __future__ import annotations

import numpy as np


def approach_signs(q: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """(N, n) -1/0/+1 from joint values q (N, n) in measurement order (any angle unit; ``tol`` in that unit).

    Row i holds ``sign(q[i] - q[i-1])`` per joint; a joint that did not move (``|dq| <= tol``) keeps its previous
    sign; row 0, and a joint that has not moved yet, is 0.
    """
    q = np.asarray(q, float)
    n_rows, n_joints = q.shape
    step = np.zeros((n_rows, n_joints))
    if n_rows > 1:
        dq = np.diff(q, axis=0)
        step[1:] = np.where(np.abs(dq) > tol, np.sign(dq), 0.0)
    rows = np.where(step != 0.0, np.arange(n_rows)[:, None], 0)
    last_move = np.maximum.accumulate(rows, axis=0)
    return step[last_move, np.arange(n_joints)[None, :]]


def next_approach(previous: np.ndarray | None, q_prev: np.ndarray | None, q_next: np.ndarray,
                  tol: float = 1e-9) -> np.ndarray:
    """The approach signs (n,) after moving from q_prev to q_next, the same rule as :func:`approach_signs` applied
    one stop at a time (``previous`` = the signs at q_prev; None before the first stop)."""
    q_next = np.asarray(q_next, float)
    if q_prev is None or previous is None:
        return np.zeros_like(q_next)
    d = q_next - np.asarray(q_prev, float)
    return np.where(np.abs(d) > tol, np.sign(d), previous)


def moves_from_order(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(last move, the move before) per row and joint (N, n), from joint values q (N, n) in measurement order
    (same unit as q; row 0 and the move before row 1 are 0). A read-back lag scales with them."""
    q = np.asarray(q, float)
    move = np.zeros_like(q)
    move[1:] = np.diff(q, axis=0)
    prev = np.zeros_like(q)
    prev[1:] = move[:-1]
    return move, prev
