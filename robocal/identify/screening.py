"""Measurement-fault screening that cannot eat structure: a point is excluded only on measurement-side evidence.

* ``local``: its residual (measured - model, mm) is isolated against neighbours that are *actually near*, in the
  workspace and in joint space: within ``near_mm`` of it in position, and with joint differences whose SMR
  motion (|dq_j| times joint j's lever arm to the SMR, summed in quadrature) is within three times that. The
  robust z uses a local scale (the model's remaining structure, being smooth, is shared by near neighbours and
  cancels; an isolated wrong measurement does not). A point with fewer than ``min_near`` near neighbours is
  never excluded on its residual: in a sparse region nothing tells a fault from structure.
* ``tracker``: the tracker's own per-point statistic (``sigma_mm``, spread of the samples) is far above the
  campaign's typical value;
* ``repeat``: a repeated pose disagrees with the other measurements of the same pose;
* ``smr triangle`` (``smr_triangle``, 2-3 SMRs on one rigid tool): a pose whose inter-SMR distances differ from
  their medians over the campaign by more than k sigma; model-free, so it screens test points too;
* ``nest`` (``nest_misreads``): a reference-nest reading that jumps against the same nest's readings before and
  after it.

Large residuals that are *not* local faults are kept: when they are clustered (their near neighbours are large
too) the model is incomplete, which ``structure_note`` says. Everything is vectorised over points (scipy k-d
tree for the neighbour search).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from robocal.kinematics.models import Kinematics, chain, smr_base

CHI3_MEDIAN = 1.5382          # median of the chi distribution with 3 degrees of freedom
NEAR_FRACTION = 0.13          # "near": within 13 % of the robot's reach (IRB 2600: 300 mm; UR5: 160 mm)
JOINT_FACTOR = 3.0            # joint motion may reach three times that (joint motions partly cancel in position)
MIN_NEAR = 4                  # near neighbours needed before a residual can be called isolated
MAX_NEIGHBOURS = 32
CHUNK_ROWS = 8192              # rows per block of the neighbour arrays (bounded memory at any N)
Z_LOCAL = 7.0                 # robust z of an isolated residual (structure gives the statistic a tail to ~6)


@dataclass(frozen=True)
class Excluded:
    """One excluded point: row index (into the arrays given), reason and its score (robust z)."""
    index: int
    reason: str
    score: float


@dataclass(frozen=True, eq=False)
class ScreenResult:
    """``keep`` (N,) bool; ``excluded`` the rejected rows with reasons; ``z_local`` (N,) robust score of each
    residual against its near neighbours (nan with fewer than ``min_near``); ``n_near`` (N,) near neighbours;
    ``large_kept`` (N,) bool: large residuals kept as structure; ``clustered`` fraction of their near
    neighbours that are large too (nan when there are none)."""
    keep: np.ndarray
    excluded: tuple[Excluded, ...]
    z_local: np.ndarray
    n_near: np.ndarray
    large_kept: np.ndarray
    clustered: float

    def structure_note(self) -> str | None:
        n = int(self.large_kept.sum())
        if n < 3 or not self.clustered >= 0.3:
            return None
        return (f"{n} points with large residuals kept: they are clustered ({100 * self.clustered:.0f} % of their "
                "near neighbours are large too), so the model is incomplete there, not the measurements")


def reach_mm(kin: Kinematics) -> float:
    """Upper bound (mm) of the SMR's distance from the base: sum of |a|, |d| and |p_flange_smr|."""
    return float(np.sum(np.abs(kin.a_mm)) + np.sum(np.abs(kin.d_mm)) + np.linalg.norm(kin.p_flange_smr_mm))


def joint_levers_mm(kin: Kinematics, q_rad: np.ndarray) -> np.ndarray:
    """(N, n) lever arm of every joint to the SMR (mm per rad of that joint): |axis_j x (p_smr - o_j)|."""
    q = np.atleast_2d(q_rad)
    if len(q) > CHUNK_ROWS:                         # row blocks: no (N, n, 3) frames
        return np.concatenate([joint_levers_mm(kin, q[b]) for b in _blocks(len(q))])
    c = chain(kin, q, full=False)
    p = smr_base(kin, q, c.T_base_flange)
    return np.linalg.norm(np.cross(c.axis, p[:, None, :] - c.origin), axis=2)


def near_neighbours(q_rad: np.ndarray, p_mm: np.ndarray, lever_mm: np.ndarray, near_mm: float,
                    k_max: int = MAX_NEIGHBOURS) -> tuple[np.ndarray, np.ndarray]:
    """(idx (N, K), valid (N, K)): up to ``k_max`` neighbours of every point within ``near_mm`` in position
    whose joint differences move the SMR by at most ``JOINT_FACTOR * near_mm`` (sqrt(sum_j (dq_j lever_j)^2),
    levers averaged over the two poses: a neighbour in another configuration or far in one joint is not near)."""
    n = len(p_mm)
    k = min(k_max, n - 1)
    tree = cKDTree(p_mm)
    idx, valid = np.empty((n, k + 1), np.int32 if n < 2**31 else np.intp), np.empty((n, k + 1), bool)
    for b in _blocks(n):                               # row blocks: no (N, K) distances, no (N, K, n) temporaries
        dist, nb = tree.query(p_mm[b], k=k + 1, distance_upper_bound=near_mm)
        dist, nb = dist.reshape(len(dist), -1), nb.reshape(len(nb), -1)
        valid[b] = np.isfinite(dist) & (nb != np.arange(b.start, b.start + len(nb))[:, None])   # not the point itself
        idx[b] = nb = np.where(valid[b], nb, 0)
        lever = 0.5 * (lever_mm[b, None, :] + lever_mm[nb])
        d_joint = np.sqrt(np.sum(((q_rad[b, None, :] - q_rad[nb]) * lever) ** 2, axis=2))
        valid[b] &= d_joint <= JOINT_FACTOR * near_mm
    return idx, valid


def _blocks(n: int) -> list[slice]:
    """Row blocks of ``CHUNK_ROWS`` (the per-neighbour arrays (N, K, ...) one block at a time)."""
    return [slice(s, s + CHUNK_ROWS) for s in range(0, max(n, 1), CHUNK_ROWS)]


def _nan_median(x: np.ndarray, axis: int) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)             # rows without any value stay nan
        return np.nanmedian(x, axis=axis)


def _local_scores(r: np.ndarray, idx: np.ndarray, valid: np.ndarray, min_near: int) -> np.ndarray:
    """Robust z (N,) of each residual against the component-wise median of its near neighbours' residuals,
    scaled by the larger of the campaign's and the neighbourhood's median deviation (chi_3 median -> sigma);
    nan where fewer than ``min_near`` neighbours are near."""
    count = valid.sum(axis=1)
    d = np.concatenate([np.linalg.norm(r[b] - _nan_median(np.where(valid[b, :, None], r[idx[b]], np.nan), 1), axis=1)
                        for b in _blocks(len(r))])                   # nan without neighbours
    ok = count >= min_near
    if not ok.any():
        return np.full(len(r), np.nan)
    s_global = float(np.median(d[ok]))
    s_local = np.concatenate([_nan_median(np.where(valid[b], d[idx[b]], np.nan), 1) for b in _blocks(len(r))])
    sigma = np.maximum(s_global, np.nan_to_num(s_local, nan=0.0)) / CHI3_MEDIAN
    return np.where(ok, d / np.maximum(sigma, 1e-12), np.nan)


def screen(q_rad: np.ndarray, p_work_mm: np.ndarray, r_mm: np.ndarray, lever_mm: np.ndarray, near_mm: float,
           sigma_mm: np.ndarray | None = None, repeat_groups: list[np.ndarray] | None = None,
           z_max: float = 6.0, z_local: float = Z_LOCAL, min_near: int = MIN_NEAR,
           neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> ScreenResult:
    """Screen calibration points for measurement faults.

    q_rad (N, n) joints; p_work_mm (N, 3) positions (any Cartesian frame); r_mm (N, 3) residuals of the current
    model; lever_mm (N, n) joint lever arms (``joint_levers_mm``); near_mm the neighbourhood radius
    (``NEAR_FRACTION`` of the reach); sigma_mm (N,) optional tracker statistic per point; repeat_groups optional
    row-index groups of the same pose; neighbours optional ``near_neighbours(q_rad, p_work_mm, lever_mm,
    near_mm)`` of these points when already known (the search depends on the poses only, not on the residuals;
    ``lever_mm`` is then unused). A point is a local fault when it has ``min_near`` near neighbours and its
    robust z exceeds ``z_local``; tracker statistics and repeats use ``z_max`` (6 sigma: about 1e-6 false alarms
    per point under Gaussian noise)."""
    q = np.asarray(q_rad, float)
    r = np.asarray(r_mm, float)
    p = np.asarray(p_work_mm, float)
    n = len(q)
    keep = np.ones(n, bool)
    out: list[Excluded] = []
    if n < 2 * min_near:
        nan = np.full(n, np.nan)
        return ScreenResult(keep, (), nan, np.zeros(n, int), np.zeros(n, bool), float("nan"))
    idx, valid = neighbours if neighbours is not None else near_neighbours(q, p, np.asarray(lever_mm, float), near_mm)
    z = _local_scores(r, idx, valid, min_near)
    n_near = valid.sum(axis=1)
    local = np.nan_to_num(z, nan=0.0) > z_local
    for i in np.flatnonzero(local):
        out.append(Excluded(int(i), f"residual {np.linalg.norm(r[i]):.3f} mm is isolated against its {n_near[i]} "
                            f"near neighbours (robust z {z[i]:.1f}; near: within {near_mm:.0f} mm in position "
                            f"and {JOINT_FACTOR * near_mm:.0f} mm of joint motion)", float(z[i])))
    keep &= ~local
    keep &= ~_tracker_outliers(sigma_mm, keep, z_max, out)
    keep &= ~_repeat_outliers(r, repeat_groups, keep, z_max, out)
    # large residuals that stay: structure, not faults
    e = np.linalg.norm(r, axis=1)
    large = keep & (e > 4.0 * np.median(e[keep]) / CHI3_MEDIAN)
    clustered = float("nan")
    has = large & (n_near > 0)
    if has.any():
        clustered = float(np.sum(large[idx[has]] & valid[has]) / np.sum(valid[has]))
    return ScreenResult(keep, tuple(sorted(out, key=lambda x: x.index)), z, n_near, large, clustered)


def _tracker_outliers(sigma_mm, keep, z_max, out: list[Excluded]) -> np.ndarray:
    """Points whose tracker statistic is far above the campaign's typical value (appends their reasons)."""
    bad = np.zeros(len(keep), bool)
    if sigma_mm is None:
        return bad
    s = np.asarray(sigma_mm, float)
    ok = np.isfinite(s)
    if ok.sum() < 10:
        return bad
    med = np.median(s[ok])
    mad = 1.4826 * np.median(np.abs(s[ok] - med))
    bad = ok & (s > med + z_max * max(mad, 1e-9)) & (s > 3.0 * med) & keep
    for i in np.flatnonzero(bad):
        out.append(Excluded(int(i), f"tracker statistic {s[i]:.4f} mm against a typical {med:.4f} mm",
                            float((s[i] - med) / max(mad, 1e-9))))
    return bad


def _repeat_outliers(r, repeat_groups, keep, z_max, out: list[Excluded]) -> np.ndarray:
    """Repeats of a pose (groups of >= 3) that disagree with the others (appends their reasons)."""
    bad = np.zeros(len(keep), bool)
    for g in repeat_groups or []:
        if len(g) < 3:
            continue
        c = np.median(r[g], axis=0)
        dev = np.linalg.norm(r[g] - c, axis=1)
        scale = max(np.median(dev), 1e-9) / CHI3_MEDIAN
        for i, dv in zip(g, dev):
            if keep[i] and dv > z_max * scale and dv > 3 * np.median(dev):
                bad[i] = True
                out.append(Excluded(int(i), f"repeat disagrees with its pose's other measurements by {dv:.3f} mm",
                                    float(dv / scale)))
    return bad


# ------------------------------------------------------------------------------------------------ SMR triangle
TRIANGLE_FLOOR_MM = 0.05       # a distance change below this is never called a fault
RIGID_SIGMA_MM = 0.5           # robust spread of an SMR distance above this: not one rigid tool


@dataclass(frozen=True, eq=False)
class TriangleScreen:
    """The inter-SMR distances of a multi-SMR tool over the poses: ``d_mm`` (N, P) per pose and pair (d12[, d13,
    d23]), their ``median_mm`` and robust ``sigma_mm`` (P,) over the poses; ``keep`` (N,) bool; ``excluded`` the
    faulty poses with reasons; ``rigid`` False when a distance is not constant at all (``why`` says which)."""
    d_mm: np.ndarray
    median_mm: np.ndarray
    sigma_mm: np.ndarray
    keep: np.ndarray
    excluded: tuple[Excluded, ...]
    rigid: bool
    why: str = ""


def _pairs(s: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(s) for j in range(i + 1, s)]


def smr_triangle(p_tracker_mm: np.ndarray, cov_mm2: np.ndarray | None = None, z_max: float = 6.0,
                 floor_mm: float = TRIANGLE_FLOOR_MM, rigid_sigma_mm: float = RIGID_SIGMA_MM) -> TriangleScreen:
    """Screen the poses of a 2-3 SMR tool (p_tracker_mm (S, N, 3), mm) on its rigidity alone (no model).

    Each distance's deviation from its median over the campaign is divided by its expected noise at that pose
    (from ``cov_mm2`` (S, N, 3, 3) when given: u^T (C_i + C_j) u along the pair; the tracker's noise grows with
    the distance), then by the robust sigma (1.4826 MAD) of those ratios; a pose whose root-sum-square score
    over its distances exceeds ``z_max`` and whose largest change exceeds ``floor_mm`` is a measurement fault.
    With three SMRs the faulty SMR is the one the changed distances share. A distance whose robust spread
    exceeds ``rigid_sigma_mm`` means the SMRs are not on one rigid tool (``rigid`` False). A fault normal to the
    SMR triangle changes no distance to first order: that direction is blind."""
    P = np.asarray(p_tracker_mm, float)
    pairs = _pairs(len(P))
    diff = np.stack([P[i] - P[j] for i, j in pairs], axis=1)                            # (N, pairs, 3)
    d = np.linalg.norm(diff, axis=2)
    med = np.median(d, axis=0)
    dev = d - med
    sigma = np.maximum(1.4826 * np.median(np.abs(dev), axis=0), 1e-4)
    names = [f"d{i + 1}{j + 1}" for i, j in pairs]
    worst = int(np.argmax(sigma))
    if sigma[worst] > rigid_sigma_mm:
        why = (f"SMR distance {names[worst]} varies by {sigma[worst]:.2f} mm (robust sigma) over {len(d)} poses "
               f"(median {med[worst]:.2f} mm): the SMRs are not on one rigid tool")
        return TriangleScreen(d, med, sigma, np.ones(len(d), bool), (), False, why)
    e = dev
    if cov_mm2 is not None:
        C = np.asarray(cov_mm2, float)
        u = diff / np.maximum(d[..., None], 1e-9)
        var = np.stack([np.einsum("ni,nij,nj->n", u[:, k], C[i] + C[j], u[:, k]) for k, (i, j) in enumerate(pairs)],
                       axis=1)
        e = dev / np.sqrt(np.maximum(var, 1e-12))
    z = e / np.maximum(1.4826 * np.median(np.abs(e), axis=0), 1e-12)
    score = np.sqrt(np.sum(z**2, axis=1))
    bad = (score > z_max) & (np.abs(dev).max(axis=1) > floor_mm)
    out = []
    for n in np.flatnonzero(bad):
        big = np.abs(z[n]) > z_max / 2
        which = ", ".join(f"{names[k]} by {dev[n, k]:+.3f} mm" for k in np.flatnonzero(big))
        smr = ""
        if len(P) == 3 and big.sum() == 2:
            shared = set(pairs[np.flatnonzero(big)[0]]) & set(pairs[np.flatnonzero(big)[1]])
            smr = f" (SMR {shared.pop() + 1})"
        out.append(Excluded(int(n), f"SMR distances off their medians: {which or 'all slightly'}{smr}, robust z "
                                    f"{score[n]:.0f}: a measurement fault", float(score[n])))
    return TriangleScreen(d, med, sigma, ~bad, tuple(out), True)


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
