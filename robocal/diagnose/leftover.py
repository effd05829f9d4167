"""Where the residual lies (geometric and final model, held-out residuals) and what is left unexplained.

Unexplained structure has one definition (``leftover``): the excess of the final model's held-out RMS over the
noise floor, sqrt(max(R^2 - F^2, 0)), and how much a non-parametric layer (GPR over the joints, reprocess's residual
layer, fitted on the calibration residuals) removes of it on held-out points. The terminal, the JSON and the HTML report print these
same numbers; ``unexplained`` is true when R exceeds the floor (inflated for the fitted parameters) by more than
``unexplained_ratio`` (and, for a floor from repeats, significantly: F test with the floor's degrees of freedom). The neighbour test (``structure_test``) then says along which inputs the leftover lies.
"""
from __future__ import annotations

import math

import numpy as np

from robocal.kinematics.models import JACOBIAN_ROWS, jacobian_blocks, joint_motion_columns
from robocal.layers.joint_gp import joint_directions
from robocal.layers.choice import fit_layer
from robocal.measure.stats import f_isf, paired_gain
from .records import DiagnosisInput
from .regions import structure_test, where_analysis
from .remainder import RemainderEvidence, classify, noise_shape, nugget, readback_jitter


def floor_scale(inp: DiagnosisInput) -> float:
    """Factor on the covariance so that its RMS equals the reported noise floor."""
    spec = math.sqrt(float(np.mean(np.trace(inp.cov_mm2, axis1=1, axis2=2))))
    return (inp.noise_floor_mm / spec) ** 2 if spec > 0 and inp.noise_floor_mm > 0 else 1.0


def _base(kin, p_tracker):
    T = kin.T_tracker_base
    return (np.asarray(p_tracker, float) - T[:3, 3]) @ T[:3, :3]


def _motion_columns(kin, q) -> tuple[np.ndarray, np.ndarray]:
    """(SMR positions (N, 3) mm, tracker frame; their ``joint_motion_columns`` (N, 3, n)), in row blocks (the
    Jacobian of the other parameters is not kept)."""
    p, J = np.empty((len(q), 3)), None
    for b, pb, Jt in jacobian_blocks(kin, q, JACOBIAN_ROWS):
        Jb = joint_motion_columns(kin, Jt.transpose(1, 2, 0))
        if J is None:
            J = np.empty((len(q), 3, Jb.shape[2]))
        p[b], J[b] = pb, Jb
    return p, J


def where_stages(inp, opt, fit, test, models, resid, cv_vec, stages, meta):
    """(regions of the geometric model, maps of both) from held-out residuals: cross-validated on the fit rows,
    plus the test rows. The final model's regions are in ``maps["_final_regions"]``."""
    out, maps = [], {}
    rows = np.concatenate([fit, test])
    for name, model, r, cv, stage in zip(("geometric", "final"), models, resid, cv_vec, stages):
        kin = getattr(model, "kinematics", model)
        held = np.concatenate([cv, r[test]]) if len(test) else cv
        regs, mp = where_stages_of(inp, opt, rows, kin, held, stage["n_params"], len(fit), meta, name)
        maps[name] = mp
        if name == "geometric":
            out += regs
        else:
            maps["_final_regions"] = regs
    return out, maps


def where_stages_of(inp, opt, rows, kin, held, n_params: int, n_fit: int, meta, name: str, every: bool = False):
    """(regions, maps) of held-out residuals ``held`` (M, 3) mm at ``rows`` of a model with ``n_params``
    parameters fitted on ``n_fit`` rows (``every``: all regions, not only those flagged above the floor)."""
    inflate = 1.0 + opt.cv_param_inflation * n_params / (3.0 * n_fit)
    cov = inp.cov_mm2[rows] * floor_scale(inp) * inflate
    p_model, Jq = _motion_columns(kin, inp.q_rad[rows])
    sub = lambda key: None if meta.get(key) is None else np.asarray(meta[key])[rows]  # noqa: E731
    return where_analysis(name, held, cov, _base(kin, p_model), inp.q_rad[rows], kin.T_tracker_base, sub("t_s"),
                          sub("approach"), sub("payload_kg"), Jq, opt, every)


def _layer_heldout(opt, model, q, p, fit, test, fold, meta, kind: str = "gpr", floor_mm: float | None = None
                   ) -> tuple[np.ndarray, str, object]:
    """(residual vectors (M, 3) mm left on held-out points once a non-parametric layer of the calibration
    (``kind``: GPR over the joints, or the joint-error GP; ``robocal.layers.choice.fit_layer``) is fitted on the final
    model's calibration residuals (at most ``layer_max_points`` of them, a seeded subset): on the test rows, or
    over the fit rows' pose blocks; "test" | "cv"; the layer fitted on all fit rows, or None in cv)."""
    kin = model.kinematics
    rng = np.random.default_rng(opt.seed)
    sub = lambda rows: {k: (None if v is None else np.asarray(v)[rows]) for k, v in meta.items()}  # noqa: E731

    def layer_errors(tr, te):
        if len(tr) > opt.layer_max_points:
            tr = np.sort(rng.choice(tr, opt.layer_max_points, replace=False))
        lay = fit_layer(kind, model, q[tr], p[tr], sub(tr), seed=opt.seed, noise_floor_mm=floor_mm)
        pm = model.kinematic_smr_base(q[te], sub(te))
        return _base(kin, p[te]) - pm - (0.0 if lay is None else lay.predict(q[te], pm)), lay
    if len(test):
        err, lay = layer_errors(fit, test)
        return err, "test", lay
    out = np.empty((len(fit), 3))
    for f in np.unique(fold):
        out[fold == f] = layer_errors(fit[fold != f], fit[fold == f])[0]
    return out, "cv", None


def joint_curves(opt, model, q, p, fit, meta, floor_mm: float, lay=None) -> tuple[list[dict], object]:
    """(each joint's angle-error curve of the joint-error GP fitted on the final model's calibration residuals
    (at most ``layer_max_points`` rows, a seeded subset; ``lay``: that fit when already made), largest first: its
    RMS over the joint's range (arcsec) and how far it moves the SMR at those rows (RMS, mm); the layer)."""
    rows = fit if len(fit) <= opt.layer_max_points else \
        np.sort(np.random.default_rng(opt.seed).choice(fit, opt.layer_max_points, replace=False))
    sub = {k: (None if v is None else np.asarray(v)[rows]) for k, v in meta.items()}
    if lay is None:
        lay = fit_layer("joint_gp", model, q[rows], p[rows], sub, noise_floor_mm=floor_mm)
    if lay is None:
        return [], None
    moved = joint_directions(lay.kinematics, q[rows], lay.joints) * lay.curves_rad(q[rows])[:, None, :]
    mm = np.sqrt(np.mean(np.sum(moved**2, axis=1), axis=0))
    arcsec = lay.curve_rms_rad()
    out = [{"joint": int(j) + 1, "rms_arcsec": float(np.degrees(arcsec[int(j) + 1]) * 3600), "rms_mm": float(v)}
           for j, v in zip(lay.joints, mm)]
    return sorted(out, key=lambda c: -c["rms_mm"]), lay


def leftover(inp, opt, fit, test, model, resid, cv_final, stage, fold, meta):
    """(unexplained_structure dict, neighbour structure tests, notes, the remainder's class, held-out error
    vectors {"final", "gpr", "joint_gp"} (M, 3) mm of the final model alone and with each layer) of the final
    model."""
    F = float(inp.noise_floor_mm)
    held = resid[test] if len(test) else cv_final
    R = float(np.sqrt(np.mean(np.sum(held**2, axis=1))))
    lay, where, _ = _layer_heldout(opt, model, np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float), fit,
                                   test, fold, meta)
    R_lay = float(np.sqrt(np.mean(np.sum(lay**2, axis=1))))
    q_all, p_all = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float)
    lay_j, _, jgp = _layer_heldout(opt, model, q_all, p_all, fit, test, fold, meta, "joint_gp", F)
    R_joint = float(np.sqrt(np.mean(np.sum(lay_j**2, axis=1))))
    curves, _ = joint_curves(opt, model, q_all, p_all, fit, meta, F, jgp)
    inflate = math.sqrt(1.0 + opt.cv_param_inflation * stage["n_params"] / (3.0 * len(fit)))
    excess = math.sqrt(max(R**2 - F**2, 0.0))
    removes = math.sqrt(max(R**2 - R_lay**2, 0.0))
    ratio = opt.unexplained_ratio
    if inp.noise_floor_dof:              # a floor measured from repeats is an estimate: F test of the two variances
        ratio = max(ratio, math.sqrt(float(f_isf(opt.floor_f_alpha, 3 * len(held), 3 * inp.noise_floor_dof))))
    flagged = bool(R > ratio * F * inflate)
    # along which inputs the leftover lies (in-sample residuals of the fit rows, whitened to the floor; at most
    # ``structure_max_points`` of them, a seeded subset: the permutation test holds N x 3 x permutations numbers)
    rows = fit if len(fit) <= opt.structure_max_points else \
        np.sort(np.random.default_rng(opt.seed).choice(fit, opt.structure_max_points, replace=False))
    cov = inp.cov_mm2[rows] * floor_scale(inp)
    w = np.linalg.solve(np.linalg.cholesky(cov), resid[rows][:, :, None])[:, :, 0]
    pb = _base(model.kinematics, inp.p_mm[rows] - resid[rows])
    q = np.asarray(inp.q_rad, float)[rows]
    spaces = {"joint space": q, "workspace": pb, "reach": np.hypot(pb[:, 0], pb[:, 1]), "height": pb[:, 2]}
    spaces.update({f"J{j + 1}": q[:, j] for j in range(q.shape[1])})
    for key, name in (("t_s", "time"), ("order", "measurement order")):
        v = meta.get(key)
        if v is not None and np.ptp(np.asarray(v, float)[rows]) > 0:
            spaces[name] = np.asarray(v, float)[rows]
    tests = structure_test(w, spaces, np.random.default_rng(opt.seed), opt.neighbours, opt.permutations)
    along = sorted((s for s in tests if tests[s]["z"] >= opt.structure_z), key=lambda s: -tests[s]["z"])
    held_err = {"final": held, "gpr": lay, "joint_gp": lay_j}
    rem = _remainder(inp, opt, model, resid[rows], rows, cov, R, F, flagged, held_err, tests, along, stage, fit)
    evaluated = "held-out test points" if where == "test" else "cross-validated calibration points"
    text = (f"unexplained structure: {excess:.3f} mm RMS over the noise floor after the final model (held-out "
            f"{R:.3f} mm vs floor {F:.3f} mm, {evaluated}); a non-parametric layer (GPR over the joints) removes "
            f"{removes:.3f} mm of it ({R:.3f} -> {R_lay:.3f} mm on the same points)")
    removes_j = math.sqrt(max(R**2 - R_joint**2, 0.0))
    text += (f"; one angle-error curve per joint (joint GP) removes {removes_j:.3f} mm ({R:.3f} -> {R_joint:.3f} mm)"
             + (": largest " + ", ".join(f"J{c['joint']} {c['rms_mm']:.3f} mm ({c['rms_arcsec']:.0f}\")"
                                         for c in curves[:3]) if curves else ""))
    if along:
        text += f"; strongest along {', '.join(along[:4])}"
    structure_left = flagged and rem.kind == "structure"
    if structure_left:
        summary = text
    elif rem.kind == "noise":
        summary = f"excess noise: {rem.text}"
    else:
        summary = (f"nothing unexplained: held-out {R:.3f} mm vs floor {F:.3f} mm (a non-parametric layer gives "
                   f"{R_lay:.3f} mm)")
    out = {"unexplained": structure_left, "heldout_rms_mm": R, "floor_mm": F, "excess_over_floor_mm": excess,
           "layer": "GPR over the joints (the residual layer of reprocess)",
           "layer_heldout_rms_mm": R_lay, "layer_removes_mm": removes, "evaluation": where, "along": along,
           "joint_layer_heldout_rms_mm": R_joint, "joint_layer_removes_mm": removes_j, "joint_curves": curves,
           "above_floor": flagged, "remainder_kind": rem.kind, "text": summary, "detail": text}
    notes = [summary] if flagged else []
    if inp.noise_floor_source == "repeats" and R < 0.8 * F:
        notes.append(f"the repeat scatter ({F:.3f} mm) exceeds the final held-out residual ({R:.3f} mm): the repeated "
                     "poses probably include approach-direction or drift effects, so the floor is overestimated")
    structure = {"tests": tests, "structure_along": along}
    return out, structure, notes, rem, held_err


def best_layer(held_err: dict) -> tuple[str, np.ndarray]:
    """(name, held-out error vectors) of the layer (GPR or joint GP) with the lower held-out RMS."""
    names = {"gpr": "GPR over the joints", "joint_gp": "joint GP"}
    k = min(("gpr", "joint_gp"), key=lambda k: float(np.mean(np.sum(held_err[k] ** 2, axis=1))))
    return names[k], held_err[k]


def _remainder(inp, opt, model, r_rows, rows, cov_rows, R, F, flagged, held_err, tests, along, stage, fit):
    """The remainder's class from its evidence (``robocal.diagnose.remainder``)."""
    name, lay = best_layer(held_err)
    gain = paired_gain(np.sum(held_err["final"] ** 2, axis=1), np.sum(lay**2, axis=1))
    q = np.asarray(inp.q_rad, float)[rows]
    kin = model.kinematics
    _, Jq = _motion_columns(kin, q)
    dof = stage["n_params"] / (3.0 * len(fit))
    S = max([tests[s]["S"] for s in along] or [0.0])
    jitter = None
    if inp.q_cmd_rad is not None:
        m = inp.meta()
        cal = np.flatnonzero(inp.calib)
        sub = lambda k: None if m.get(k) is None else np.asarray(m[k])[cal]  # noqa: E731
        jitter = readback_jitter(np.asarray(inp.q_rad)[cal], np.asarray(inp.q_cmd_rad)[cal], sub("move"),
                                 sub("prev_move"))
    ev = RemainderEvidence(R, F, flagged, name, gain.rms_cand_mm, gain.t, S * F**2 / 3.0,
                           along[0] if along else None, nugget(r_rows, q, dof_share=dof),
                           noise_shape(r_rows, cov_rows, Jq), jitter,
                           np.sqrt(np.mean(np.sum(Jq**2, axis=1), axis=0)), inp.noise_floor_source)
    return classify(ev)
