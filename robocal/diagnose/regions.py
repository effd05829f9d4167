"""Where the residual lies: regions of the workspace, joint ranges, base axes, time, approach direction and
payload above the noise floor (``where_analysis``), maps for plots, and the neighbour test that says along which
inputs a leftover lies (``structure_test``)."""
from __future__ import annotations

from typing import Mapping

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from robocal.effects.cv import spread_scaled
from robocal.measure.stats import chi2_sf, f_sf, welch_t

from .records import DiagnosisOptions, Region


def _region_stats(r_b, w, floor_pt, idx):
    """(rms, floor, p) of residuals r_b (m, 3) mm / whitened w (m, 3) over indices idx."""
    k = len(idx)
    rms = float(np.sqrt(np.mean(np.sum(r_b[idx] ** 2, axis=1))))
    floor = float(np.sqrt(np.mean(floor_pt[idx] ** 2)))
    chi = float(np.sum(w[idx] ** 2))
    return rms, floor, float(chi2_sf(chi, 3 * k))


def _edges(x, k):
    return np.quantile(x, np.linspace(0, 1, k + 1)[1:-1])


def _words_band(name, unit, lo, hi, labels, i, k):
    """'far reach (radius > 1300 mm)' style description of band i of k."""
    word = labels[i] if k == len(labels) else f"band {i + 1}/{k}"
    if i == 0:
        return f"{word} ({name} < {hi:.0f} {unit})"
    if i == k - 1:
        return f"{word} ({name} > {lo:.0f} {unit})"
    return f"{word} ({name} {lo:.0f}-{hi:.0f} {unit})"


def where_analysis(stage: str, r_mm: np.ndarray, cov_eff: np.ndarray, p_base: np.ndarray, q_rad: np.ndarray,
                   R_tracker_base: np.ndarray, t_s=None, approach=None, payload=None, Jq=None,
                   options: DiagnosisOptions = DiagnosisOptions(), every: bool = False) -> tuple[list[Region], dict]:
    """Map residuals r_mm (m, 3, tracker frame) with their expected covariance cov_eff (m, 3, 3) over the
    workspace, joint ranges, base axes, time, approach direction and payload. Returns (flagged regions sorted by
    RMS/floor, full maps for plots; ``every``: every region, flagged or not); a region's ``share`` is the part
    of the squared error over the floor it holds."""
    m = len(r_mm)
    R = np.asarray(R_tracker_base)[:3, :3]
    r_b = r_mm @ R                                    # base frame (R^T r)
    Lc = np.linalg.cholesky(cov_eff)
    w = np.linalg.solve(Lc, r_mm[:, :, None])[:, :, 0]
    floor_pt = np.sqrt(np.trace(cov_eff, axis1=1, axis2=2))
    cands: list[tuple[str, str, np.ndarray, dict]] = [("all evaluated points", "all", np.arange(m), {})]
    maps: dict = {}
    radius, z = np.hypot(p_base[:, 0], p_base[:, 1]), p_base[:, 2]
    er, ez = _edges(radius, 3), _edges(z, 3)
    br, bz = np.digitize(radius, er), np.digitize(z, ez)
    rl = ("near reach", "mid reach", "far reach")
    zl = ("low", "mid height", "high")
    bounds_r = np.concatenate([[radius.min()], er, [radius.max()]])
    bounds_z = np.concatenate([[z.min()], ez, [z.max()]])
    for i in range(3):
        cands.append((_words_band("radius", "mm", bounds_r[i], bounds_r[i + 1], rl, i, 3), "workspace",
                      np.flatnonzero(br == i), {}))
        cands.append((_words_band("z", "mm", bounds_z[i], bounds_z[i + 1], zl, i, 3), "workspace",
                      np.flatnonzero(bz == i), {}))
    for i in range(3):
        for k in range(3):
            idx = np.flatnonzero((br == i) & (bz == k))
            d1 = _words_band("radius", "mm", bounds_r[i], bounds_r[i + 1], rl, i, 3)
            d2 = _words_band("z", "mm", bounds_z[k], bounds_z[k + 1], zl, k, 3)
            desc = f"{rl[i]}, {zl[k]} ({d1.split('(')[1][:-1]}, {d2.split('(')[1][:-1]})"
            cands.append((desc, "workspace cell", idx, {}))
    maps["workspace"] = _grid_map(radius, z, r_b, floor_pt)
    qd = np.degrees(q_rad)
    maps["joints"] = []
    for j in range(q_rad.shape[1]):
        e = _edges(qd[:, j], 4)
        b = np.digitize(qd[:, j], e)
        lim = np.concatenate([[qd[:, j].min()], e, [qd[:, j].max()]])
        for i in range(4):
            cands.append((f"J{j + 1} in {lim[i]:.0f} to {lim[i + 1]:.0f} deg", "joint range", np.flatnonzero(b == i),
                          {"joint": j + 1}))
        maps["joints"].append(_line_map(qd[:, j], r_b, floor_pt, 8, f"J{j + 1} (deg)"))
    if t_s is not None and np.ptp(t_s) > 0:
        tm = (np.asarray(t_s) - np.min(t_s)) / 60.0
        e = _edges(tm, 6)
        b = np.digitize(tm, e)
        lim = np.concatenate([[tm.min()], e, [tm.max()]])
        for i in range(6):
            cands.append((f"t {lim[i]:.0f}-{lim[i + 1]:.0f} min", "time", np.flatnonzero(b == i), {}))
        maps["time"] = _line_map(tm, r_b, floor_pt, 12, "t (min)")
    if payload is not None:
        vals = np.unique(np.round(payload, 3))
        if len(vals) > 1:
            for v in vals:
                cands.append((f"payload {v:g} kg", "payload", np.flatnonzero(np.round(payload, 3) == v), {}))
    regions = []
    m_tests = len(cands) + 3 + (q_rad.shape[1] if approach is not None else 0)
    alpha = options.region_alpha / max(m_tests, 1)
    chi_all = float(np.sum(w**2))
    excess = np.sum(r_b**2, axis=1) - floor_pt**2          # each point's share of the squared error over the floor
    total = float(np.sum(excess))
    for desc, kind, idx, extra in cands:
        if len(idx) < options.region_min_points:
            continue
        rms, floor, p = _region_stats(r_b, w, floor_pt, idx)
        if total > 0:
            extra = dict(extra, share=float(np.sum(excess[idx])) / total)
        rest = m - len(idx)
        if rest >= options.region_min_points:
            chi = float(np.sum(w[idx] ** 2))
            F = (chi / (3 * len(idx))) / max((chi_all - chi) / (3 * rest), 1e-300)
            out = np.setdiff1d(np.arange(m), idx)
            extra = dict(extra, vs_rest_ratio=rms / max(float(np.sqrt(np.mean(np.sum(r_b[out] ** 2, axis=1)))), 1e-12),
                         stands_out=bool(f_sf(F, 3 * len(idx), 3 * rest) < alpha))
        regions.append(Region(f"{desc}: RMS {rms:.3f} mm vs floor {floor:.3f} mm", rms, floor, len(idx), kind, stage,
                              p, dict(extra, region=desc)))
    # per base axis: RMS of one component vs its own floor
    cov_b = np.einsum("ji,njk,kl->nil", R, cov_eff, R)
    axes = []
    for a, name in enumerate(("x", "y", "z")):
        rms = float(np.sqrt(np.mean(r_b[:, a] ** 2)))
        fl = float(np.sqrt(np.mean(cov_b[:, a, a])))
        chi = float(np.sum(r_b[:, a] ** 2 / cov_b[:, a, a]))
        p = float(chi2_sf(chi, m))
        label = f"base {name} axis" + (" (vertical)" if name == "z" else "")
        regions.append(Region(f"{label}: RMS {rms:.3f} mm vs floor {fl:.3f} mm", rms, fl, m, "axis", stage, p,
                              {"region": label}))
        axes.append({"axis": name, "rms_mm": rms, "floor_mm": fl})
    maps["axes"] = axes
    if approach is not None and Jq is not None:
        maps["approach"] = []
        for j in range(q_rad.shape[1]):
            reg = _approach_region(j, approach[:, j], r_mm, cov_eff, Jq[:, :, j], stage, options.region_min_points)
            if reg is not None:
                regions.append(reg)
                maps["approach"].append({"joint": j + 1, **reg.extra, "rms_mm": reg.rms_mm})
    flagged = [g for g in regions if every or (g.p_value < alpha and (
        g.kind == "approach" or g.rms_mm >= options.region_min_ratio * g.floor_mm))]
    flagged.sort(key=lambda g: (g.kind != "all", not (g.kind == "approach" or g.extra.get("stands_out", False)),
                                -g.rms_mm / max(g.floor_mm, 1e-12)))
    return (flagged if every else flagged[:options.max_regions]), maps


def _approach_region(j, s, r_mm, cov, jq, stage, min_points: int = 5) -> Region | None:
    """Difference of the residual along joint j's motion between + and - approaches (Welch t)."""
    plus, minus = s > 0, s < 0
    if plus.sum() < min_points or minus.sum() < min_points:
        return None
    u = jq / np.maximum(np.linalg.norm(jq, axis=1, keepdims=True), 1e-12)
    x = np.einsum("ni,ni->n", r_mm, u)
    var = np.einsum("ni,nij,nj->n", u, cov, u)
    t, p = welch_t(x[plus], x[minus])
    shift = float(np.mean(x[plus]) - np.mean(x[minus]))
    floor = float(np.sqrt(np.mean(var)))
    rms = float(np.sqrt(np.mean(x**2)))
    return Region(f"J{j + 1} approach direction: the residual along the J{j + 1} motion differs by {abs(shift):.3f} mm "
                  f"between + and - approaches (RMS {rms:.3f} mm vs floor {floor:.3f} mm)", rms, floor, len(s),
                  "approach", stage, p, {"joint": j + 1, "shift_mm": shift, "t": t,
                                         "region": f"J{j + 1} approach direction (+ vs -), shift {shift:+.3f} mm"})


def _line_map(x, r_b, floor_pt, k, label):
    edges = np.linspace(np.min(x), np.max(x), k + 1)
    b = np.clip(np.digitize(x, edges[1:-1]), 0, k - 1)
    rms = [float(np.sqrt(np.mean(np.sum(r_b[b == i] ** 2, axis=1)))) if np.any(b == i) else None for i in range(k)]
    fl = [float(np.sqrt(np.mean(floor_pt[b == i] ** 2))) if np.any(b == i) else None for i in range(k)]
    return {"label": label, "edges": edges.tolist(), "rms_mm": rms, "floor_mm": fl,
            "n": [int(np.sum(b == i)) for i in range(k)]}


def _grid_map(radius, z, r_b, floor_pt, k=5):
    er, ez = np.linspace(radius.min(), radius.max(), k + 1), np.linspace(z.min(), z.max(), k + 1)
    br = np.clip(np.digitize(radius, er[1:-1]), 0, k - 1)
    bz = np.clip(np.digitize(z, ez[1:-1]), 0, k - 1)
    rms = [[None] * k for _ in range(k)]
    n = [[0] * k for _ in range(k)]
    for i in range(k):
        for j in range(k):
            sel = (br == i) & (bz == j)
            n[i][j] = int(sel.sum())
            if sel.any():
                rms[i][j] = float(np.sqrt(np.mean(np.sum(r_b[sel] ** 2, axis=1))))
    return {"radius_edges_mm": er.tolist(), "z_edges_mm": ez.tolist(), "rms_mm": rms, "n": n,
            "floor_mm": float(np.sqrt(np.mean(floor_pt**2)))}


def structure_test(w: np.ndarray, spaces: Mapping[str, np.ndarray], rng: np.random.Generator, k: int = 10,
                   permutations: int = 200) -> dict:
    """Neighbour correlation of whitened residual vectors w (m, 3) in each feature space (m, d): statistic
    S = mean_i w_i . mean_{j in kNN(i)} w_j, z-score against residual permutations. Under pure noise S ~ 0;
    S estimates the structured variance in noise units (3 = as large as the noise)."""
    out = {}
    m = len(w)
    perms = np.stack([rng.permutation(m) for _ in range(permutations)])
    for name, F in spaces.items():
        F = spread_scaled(np.asarray(F, float).reshape(m, -1))
        if not F.shape[1] or m <= k + 1:
            continue
        F = F + 1e-9 * rng.standard_normal(F.shape)          # break ties (repeated values)
        _, nn = cKDTree(F).query(F, k=k + 1)
        nn = nn[:, 1:]
        A = sparse.csr_matrix((np.full(m * k, 1.0 / k), nn.ravel(), np.arange(0, m * k + 1, k)), shape=(m, m))
        S = float(np.mean(np.sum(w * (A @ w), axis=1)))
        Wp = np.concatenate([w[pp] for pp in perms], axis=1)            # (m, 3 x permutations)
        Sp = np.sum((Wp * (A @ Wp)).reshape(m, len(perms), 3), axis=(0, 2)) / m
        z = float((S - Sp.mean()) / max(Sp.std(ddof=1), 1e-12))
        out[name] = {"S": S, "z": z}
    return out
