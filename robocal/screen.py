"""Measurement-fault screening that cannot eat structure.

A calibration point is excluded only when it looks like a *measurement fault*:

* ``local``: its residual (measured - model, mm) is far from the residuals of its neighbours **both** in joint
  space and in the workspace, measured against a local robust scale (the model's remaining structure, being
  smooth, is shared by neighbours and cancels; an isolated wrong measurement does not);
* ``tracker``: the tracker's own per-point statistic (``sigma_mm``, spread of the samples) is far above the
  campaign's typical value;
* ``repeat``: a repeated pose disagrees with the other measurements of the same pose.

Large residuals that are *not* local faults are kept: when they are spatially clustered (their neighbours are
large too) the model is incomplete, which ``structure_note`` says. Everything is vectorised over points
(scipy k-d trees for the neighbour searches).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

CHI3_MEDIAN = 1.5382          # median of the chi distribution with 3 degrees of freedom


@dataclass(frozen=True)
class Excluded:
    """One excluded point: row index (into the arrays given), reason and its score (robust z)."""
    index: int
    reason: str
    score: float


@dataclass(frozen=True, eq=False)
class ScreenResult:
    """``keep`` (N,) bool; ``excluded`` the rejected rows with reasons; ``z_joint``/``z_work`` (N,) local robust
    scores; ``large_kept`` (N,) bool: large residuals kept as structure; ``clustered`` fraction of their
    neighbours that are large too (nan when there are none)."""
    keep: np.ndarray
    excluded: tuple[Excluded, ...]
    z_joint: np.ndarray
    z_work: np.ndarray
    large_kept: np.ndarray
    clustered: float

    def structure_note(self) -> str | None:
        n = int(self.large_kept.sum())
        if n < 3 or not self.clustered >= 0.3:
            return None
        return (f"{n} points with large residuals kept: they are spatially clustered ({100 * self.clustered:.0f} % "
                "of their neighbours in joint space are large too), so the model is incomplete there, not the "
                "measurements")


def _local_scores(X: np.ndarray, r: np.ndarray, k: int) -> np.ndarray:
    """Robust z of each point's residual against the component-wise median of its k nearest neighbours in X,
    scaled by the larger of the global and the neighbourhood's median deviation (chi_3 median -> sigma)."""
    Xs = (X - X.mean(0)) / np.where(X.std(0) > 1e-12, X.std(0), 1.0)
    k = min(k, len(X) - 1)
    _, nn = cKDTree(Xs).query(Xs, k=k + 1)
    nn = nn[:, 1:]                                                   # drop the point itself
    m = np.median(r[nn], axis=1)                                     # (N, 3)
    d = np.linalg.norm(r - m, axis=1)                                # (N,)
    s_global = np.median(d)
    s_local = np.median(d[nn], axis=1)
    sigma = np.maximum(s_global, s_local) / CHI3_MEDIAN
    return d / np.maximum(sigma, 1e-12)


def screen(q_rad: np.ndarray, p_work_mm: np.ndarray, r_mm: np.ndarray, sigma_mm: np.ndarray | None = None,
           repeat_groups: list[np.ndarray] | None = None, k: int = 8, z_max: float = 6.0) -> ScreenResult:
    """Screen calibration points for measurement faults.

    q_rad (N, n) joints; p_work_mm (N, 3) positions (any Cartesian frame); r_mm (N, 3) residuals of the current
    model; sigma_mm (N,) optional tracker statistic per point; repeat_groups optional row-index groups of the
    same pose. A point is a local fault when its robust z exceeds ``z_max`` both in joint space and in the
    workspace (6 sigma of a 3-D deviation: about 1e-6 false alarms per point)."""
    q = np.asarray(q_rad, float)
    r = np.asarray(r_mm, float)
    n = len(q)
    keep = np.ones(n, bool)
    out: list[Excluded] = []
    if n < 12:
        z = np.zeros(n)
        return ScreenResult(keep, (), z, z, np.zeros(n, bool), float("nan"))
    z_q = _local_scores(q, r, k)
    z_p = _local_scores(np.asarray(p_work_mm, float), r, k)
    local = (z_q > z_max) & (z_p > z_max)
    for i in np.flatnonzero(local):
        out.append(Excluded(int(i), f"residual {np.linalg.norm(r[i]):.3f} mm is isolated against its neighbours "
                            f"(robust z {z_q[i]:.1f} in joint space, {z_p[i]:.1f} in the workspace)",
                            float(min(z_q[i], z_p[i]))))
    keep &= ~local
    if sigma_mm is not None:
        s = np.asarray(sigma_mm, float)
        ok = np.isfinite(s)
        if ok.sum() >= 10:
            med = np.median(s[ok])
            mad = 1.4826 * np.median(np.abs(s[ok] - med))
            bad = ok & (s > med + z_max * max(mad, 1e-9)) & (s > 3.0 * med) & keep
            for i in np.flatnonzero(bad):
                out.append(Excluded(int(i), f"tracker statistic {s[i]:.4f} mm against a typical {med:.4f} mm",
                                    float((s[i] - med) / max(mad, 1e-9))))
            keep &= ~bad
    for g in repeat_groups or []:
        if len(g) < 3:
            continue
        c = np.median(r[g], axis=0)
        dev = np.linalg.norm(r[g] - c, axis=1)
        scale = max(np.median(dev), 1e-9) / CHI3_MEDIAN
        for i, dv in zip(g, dev):
            if keep[i] and dv > z_max * scale and dv > 3 * np.median(dev):
                keep[i] = False
                out.append(Excluded(int(i), f"repeat disagrees with its pose's other measurements by {dv:.3f} mm",
                                    float(dv / scale)))
    # large residuals that stay: structure, not faults
    e = np.linalg.norm(r, axis=1)
    s_e = np.median(e[keep]) / CHI3_MEDIAN
    large = keep & (e > 4.0 * s_e)
    clustered = float("nan")
    if large.any():
        Xs = (q - q.mean(0)) / np.where(q.std(0) > 1e-12, q.std(0), 1.0)
        _, nn = cKDTree(Xs).query(Xs[large], k=min(k, n - 1) + 1)
        clustered = float(np.mean(large[nn[:, 1:]]))
    return ScreenResult(keep, tuple(sorted(out, key=lambda x: x.index)), z_q, z_p, large, clustered)


# ------------------------------------------------------------------------------------------------ reference nests
NEST_WINDOW = 3                # readings on each side a nest reading is compared with
NEST_FLOOR_MM = 0.1            # a jump below this is never called a misread (tracker noise, SMR reseating)
NEST_Z_MAX = 10.0              # the jump statistic (nearer of two sides, anisotropic noise) has a long tail


@dataclass(frozen=True, eq=False)
class NestScreen:
    """``keep`` (M,) bool over the nest readings given; ``excluded`` the misreads (row index, reason, robust z);
    ``jump_mm`` (M,) each reading's distance from the nearer of its two one-sided neighbour medians."""
    keep: np.ndarray
    excluded: tuple[Excluded, ...]
    jump_mm: np.ndarray


def _one_sided_medians(p: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(before, after) (M, 3): component-wise medians of the up to ``w`` readings before / after each reading of
    one nest in time order (NaN where a side is empty)."""
    m = len(p)
    pad = np.full((w, 3), np.nan)
    ext = np.concatenate([pad, p, pad])
    idx = np.arange(m)[:, None]
    before = ext[idx + np.arange(w)[None, :]]                    # rows i-w .. i-1
    after = ext[idx + w + 1 + np.arange(w)[None, :]]             # rows i+1 .. i+w
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # an empty side (first / last readings)
        return np.nanmedian(before, axis=1), np.nanmedian(after, axis=1)


def nest_misreads(t_s: np.ndarray, nest: np.ndarray, p_tracker_mm: np.ndarray, z_max: float = NEST_Z_MAX,
                  floor_mm: float = NEST_FLOOR_MM, window: int = NEST_WINDOW) -> NestScreen:
    """Readings of fixed reference nests that jump against their time neighbours (the tracker locked onto
    something else, a misread distance): times t_s (M,) s, nest index nest (M,), readings p_tracker_mm (M, 3) mm.

    Per nest in time order, a reading's jump is its distance from the *nearer* of the medians of the ``window``
    readings before and after it, so a nest that really moved (a step that persists) is not a misread, an
    isolated reading off both sides is. Scores are robust z against the nest's median jump (all nests' when it
    has fewer than 10 readings; chi_3 median -> sigma): the tracker noise grows with the distance of the nest.
    A misread has z > ``z_max`` and a jump > ``floor_mm``. Nests read fewer than 3 times are not screened (two
    readings cannot say which one is wrong)."""
    t = np.asarray(t_s, float)
    nest = np.asarray(nest, int)
    p = np.asarray(p_tracker_mm, float)
    jump, scale = np.zeros(len(p)), np.full(len(p), np.nan)
    screened = np.zeros(len(p), bool)
    for k in np.unique(nest):
        rows = np.flatnonzero(nest == k)
        rows = rows[np.argsort(t[rows], kind="stable")]
        if len(rows) < 3:
            continue
        before, after = _one_sided_medians(p[rows], window)
        d = np.stack([np.linalg.norm(p[rows] - before, axis=1), np.linalg.norm(p[rows] - after, axis=1)])
        jump[rows] = np.nanmin(d, axis=0)
        screened[rows] = True
        if len(rows) >= 10:
            scale[rows] = np.median(jump[rows])
    keep = np.ones(len(p), bool)
    if not screened.any():
        return NestScreen(keep, (), jump)
    scale = np.where(np.isnan(scale), np.median(jump[screened]), scale)
    z = jump / np.maximum(scale / CHI3_MEDIAN, 1e-9)
    bad = screened & (z > z_max) & (jump > floor_mm)
    keep[bad] = False
    out = tuple(Excluded(int(i), f"reading jumps {jump[i]:.3f} mm against the same nest's readings before and "
                                 f"after it (robust z {z[i]:.0f}): a misread", float(z[i])) for i in np.flatnonzero(bad))
    return NestScreen(keep, out, jump)
