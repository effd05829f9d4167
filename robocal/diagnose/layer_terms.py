"""What the residual layer carries, described: the joint-error GP (one angle-error curve per joint, the layer
``reprocess`` offers as ``joint_gp``) on the final model's calibration residuals, its gain cross-validated by the
engine's pose blocks, each joint's share of what it removes (the joint angles along which it varies most) and the
regions where it acts; then the best low-order parametric description of the structure: candidate model terms,
each scored by the held-out gain it would keep as a term of the model (geometry + the accepted effects + the
term, linearised, cross-validated on the same rows and pose blocks), as a share of the joint GP's gain.

Candidate terms (any number of joints): per joint that moves >= 20 deg a cyclic error of order 1-6
(sin, cos of h q_j), a scale and bow of the joint (q_j, q_j^2: a ratio error), a deflection of the joint growing
with the square of the horizontal reach; and a vertical sag growing with the reach (r^2, r^3).
"""
from __future__ import annotations

import math

import numpy as np

from robocal.effects.cv import BlockedCV, Blocking, design_array
from robocal.identify.whitened import whitening
from robocal.layers.joint_gp import fit_joint_gp, joint_directions
from robocal.kinematics.models import ParamLayout, identification_jacobian
from robocal.layers.choice import layer_targets
from robocal.measure.stats import paired_gain
from .budget import linear_design
from .leftover import best_layer

ORDERS = (1, 2, 3, 4, 5, 6)
MIN_SPAN_RAD = math.radians(20.0)
TOP_TERMS = 5


def candidate_terms(kin, q_rad: np.ndarray, p0: np.ndarray, J: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """[(name, regressor (N, 3, k) mm per unit)] of the candidate terms at q_rad (N, n) (``p0`` (N, 3) tracker mm
    and ``J`` (N, 3, P) the identification Jacobian at these poses)."""
    layout = ParamLayout.of(kin)
    theta = {i: c for c, i, k in layout.joint_cols if k == 0}
    T = kin.T_tracker_base
    pb = (p0 - T[:3, 3]) @ T[:3, :3]
    reach = np.hypot(pb[:, 0], pb[:, 1]) / 1000.0                      # m
    out = []
    for j in range(q_rad.shape[1]):
        if j not in theta:
            continue
        Jj = J[:, :, theta[j]]                                           # mm per rad of joint j
        qj = q_rad[:, j]
        if np.ptp(qj) >= MIN_SPAN_RAD:
            for h in ORDERS:
                out.append((f"cyclic J{j + 1} order {h}",
                            np.stack([Jj * np.sin(h * qj)[:, None], Jj * np.cos(h * qj)[:, None]], axis=2)))
            u = qj - qj.mean()
            out.append((f"scale and bow J{j + 1} (q, q^2)", np.stack([Jj * u[:, None], Jj * (u**2)[:, None]], axis=2)))
        if j < 3:
            out.append((f"J{j + 1} deflection growing with reach^2", (Jj * (reach**2)[:, None])[:, :, None]))
    up = T[:3, :3][:, 2]                                                 # base z in the tracker frame
    out.append(("vertical sag growing with the reach (r^2, r^3)",
                np.stack([np.outer(reach**2, up), np.outer(reach**3, up)], axis=2)))
    return out


def describe_layer(inp, opt, data, model, effects, fold_fit: np.ndarray, held_err: dict) -> dict:
    """The description (see the module docstring): the joint GP on the final model's residuals at the fit rows
    (at most ``layer_max_points``, a seeded subset), cross-validated by the engine's pose blocks ``fold_fit`` with
    its hyperparameters re-fitted per fold; the candidate terms on the same rows and folds. ``held_err``: the
    layers' errors on the diagnosis's held-out points (the best layer is named beside)."""
    kin_geo, cols, fit, test, meta = data
    rows_i = np.arange(len(fit))
    if len(fit) > opt.layer_max_points:
        rows_i = np.sort(np.random.default_rng(opt.seed).choice(len(fit), opt.layer_max_points, replace=False))
    rows, fold = fit[rows_i], np.asarray(fold_fit)[rows_i]
    q, p = np.asarray(inp.q_rad, float)[rows], np.asarray(inp.p_mm, float)[rows]
    m = {k: (None if v is None else np.asarray(v)[rows]) for k, v in meta.items()}
    _, _, e = layer_targets(model, q, p, m)
    lay, err = fit_joint_gp(model.kinematics, q, e, inp.noise_floor_mm, fold)
    best_name, best_err = best_layer(held_err)
    e_final = np.sum(held_err["final"] ** 2, axis=1)
    out = {"layer": "joint GP (one angle-error curve per joint)",
           "evaluation": f"cross-validation by pose blocks on {len(rows)} calibration rows",
           "best_heldout_layer": best_name,
           "best_heldout_removes_mm": math.sqrt(max(float(np.mean(e_final - np.sum(best_err**2, axis=1))), 0.0))}
    if lay is None:
        out["text"] = "no joint moves enough to carry an angle-error curve"
        return out
    e0, e1 = np.sum(e**2, axis=1), np.sum(err**2, axis=1)
    gain = paired_gain(e0, e1)
    R, Rl = gain.rms_base_mm, gain.rms_cand_mm
    gain2 = max(R**2 - Rl**2, 0.0)
    out.update(rms_before_mm=R, rms_after_mm=Rl, removes_mm=math.sqrt(gain2), t=gain.t)
    per = joint_directions(lay.kinematics, q, lay.joints) * lay.curves_rad(q)[:, None, :]
    ms = np.mean(np.sum(per**2, axis=1), axis=0)
    arcsec = lay.curve_rms_rad()
    out["joints"] = sorted(({"joint": int(j) + 1, "rms_mm": float(math.sqrt(v)),
                             "share": float(v / max(ms.sum(), 1e-300)),
                             "rms_arcsec": float(np.degrees(arcsec[int(j) + 1]) * 3600)}
                            for j, v in zip(lay.joints, ms)), key=lambda d: -d["share"])
    out["regions"] = _regions(model.kinematics, q, p, lay.predict(q))
    out["terms"] = _terms(inp, kin_geo, cols, effects, rows, q, p, m, fold, gain2)
    out["text"] = _text(out, gain2)
    return out


def _text(out: dict, gain2: float) -> str:
    best = out["terms"][0] if out["terms"] else None
    where = out["regions"][0]
    R, Rl = out["rms_before_mm"], out["rms_after_mm"]
    if gain2 <= 0 or out["t"] < 2.0:
        text = f"the joint GP removes nothing significant (cross-validated {R:.3f} -> {Rl:.3f} mm, t = {out['t']:.1f})"
    else:
        top = ", ".join(f"J{d['joint']} {100 * d['share']:.0f} %" for d in out["joints"][:3])
        text = (f"the joint GP removes {math.sqrt(gain2):.3f} mm (cross-validated {R:.3f} -> {Rl:.3f} mm, t = "
                f"{out['t']:.1f}); it varies most along {top}; it acts most in {where['region']} "
                f"({100 * where['share']:.0f} % of what it removes on {100 * where['points']:.0f} % of the points)")
    if best is not None and best["gain_mm"] > 0:
        text += (f"; best named term: {best['term']}, cross-validated {best['rms_before_mm']:.3f} -> "
                 f"{best['rms_after_mm']:.3f} mm as a model term (t = {best['t']:.1f})"
                 + (f", {100 * best['share_of_layer']:.0f} % of the joint GP's gain"
                    if gain2 > 0 and out["t"] >= 2.0 else ""))
    return text


def _regions(kin, q, p, moved) -> list[dict]:
    """Reach and height terciles and joint quartiles by the share of the layer's squared displacement they hold
    (with their share of the points), largest share first."""
    T = kin.T_tracker_base
    pb = (p - T[:3, 3]) @ T[:3, :3]
    d2 = np.sum(moved**2, axis=1)
    tot = max(float(d2.sum()), 1e-300)
    feats = {"reach": (np.hypot(pb[:, 0], pb[:, 1]), 3, ("near reach", "mid reach", "far reach"), "mm"),
             "height": (pb[:, 2], 3, ("low", "mid height", "high"), "mm")}
    feats.update({f"J{j + 1}": (np.degrees(q[:, j]), 4, None, "deg") for j in range(q.shape[1])})
    out = []
    for name, (x, k, words, unit) in feats.items():
        edges = np.quantile(x, np.linspace(0, 1, k + 1))
        b = np.clip(np.digitize(x, edges[1:-1]), 0, k - 1)
        for i in range(k):
            sel = b == i
            label = (words[i] + f" ({name} {edges[i]:.0f}-{edges[i + 1]:.0f} {unit})" if words else
                     f"{name} in {edges[i]:.0f} to {edges[i + 1]:.0f} {unit}")
            out.append({"region": label, "share": float(d2[sel].sum() / tot), "points": float(sel.mean())})
    out.sort(key=lambda r: -(r["share"] - r["points"]))
    return out[:6]


def _terms(inp, kin_geo, cols, effects, rows, q, p, m, fold, layer_gain2) -> list[dict]:
    """The candidate terms by their cross-validated gain beside geometry + the accepted effects (linearised)."""
    p0, A0, _, _ = linear_design(kin_geo, cols, q, m, effects)
    terms = candidate_terms(kin_geo, q, p0, identification_jacobian(kin_geo, q)[1])
    base_n = A0.shape[2]
    A = design_array(len(q), base_n + sum(t.shape[2] for _, t in terms))
    A[:, :, :base_n] = A0
    del A0
    at, spans = base_n, []
    for name, t in terms:
        A[:, :, at:at + t.shape[2]] = t
        spans.append((name, np.arange(at, at + t.shape[2])))
        at += t.shape[2]
    cvt = BlockedCV(A, p - p0, whitening(np.asarray(inp.cov_mm2, float)[rows], len(q)),
                    [Blocking("pose blocks", fold)], copy=False)
    del A
    base = np.arange(base_n)
    se0 = np.sum(cvt.errors(base) ** 2, axis=1)
    out = []
    for name, span in spans:
        g = paired_gain(se0, np.sum(cvt.errors(np.concatenate([base, span])) ** 2, axis=1))
        g2 = max(g.rms_base_mm**2 - g.rms_cand_mm**2, 0.0)
        out.append({"term": name, "rms_before_mm": g.rms_base_mm, "rms_after_mm": g.rms_cand_mm,
                    "gain_mm": math.sqrt(g2), "t": g.t,
                    "share_of_layer": g2 / layer_gain2 if layer_gain2 > 0 else 0.0})
    out.sort(key=lambda d: d["rms_after_mm"])
    return out[:TOP_TERMS]
