"""Repeated poses: which rows repeat a pose, and the measured noise floor they give (mm)."""
from __future__ import annotations

import numpy as np


def repeat_groups(q: np.ndarray, decimals: int = 3) -> list[np.ndarray]:
    """Row indices of repeated poses (same joints (N, n), any unit, to 10^-decimals), groups of >= 2 rows."""
    keys = np.round(np.asarray(q, float), decimals)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return [np.flatnonzero(inverse.ravel() == g) for g in np.flatnonzero(counts >= 2)]


def repeat_dof(q: np.ndarray, decimals: int = 3) -> int:
    """Degrees of freedom of :func:`noise_floor_from_repeats`: sum over repeated poses of (count - 1)."""
    return int(sum(len(g) - 1 for g in repeat_groups(q, decimals)))


def noise_floor_from_repeats(q: np.ndarray, p_mm: np.ndarray, decimals: int = 3) -> float | None:
    """sqrt of the pooled within-pose variance of the 3-D position p_mm (N, 3) (mm), or None without enough
    repeats (at least 2 repeated poses and 6 degrees of freedom)."""
    groups = repeat_groups(q, decimals)
    dof = sum(len(g) - 1 for g in groups)
    if len(groups) < 2 or dof < 6:
        return None
    ss = sum(np.sum((p_mm[g] - p_mm[g].mean(axis=0)) ** 2) for g in groups)
    return float(np.sqrt(ss / dof))
