"""``diagnose``: the effect engine's answer on one dataset, and what only the diagnosis adds to it.

The engine (``robocal.elastic``) decides which effects the data support and fits them with the geometry; the
calibration (``campaign reprocess``) uses the same answer. The diagnosis adds: how far each effect shrinks the
error on held-out points (step by step), where the residual lies (``regions``), confusable classes and the
experiment that separates them, confounds with the measurement order, consistency of each effect's parameters,
what the data cannot tell, and the unexplained structure (one definition, ``unexplained_structure``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..effects import effect_regressor
from ..elastic import BlockedCV, Blocking, ElasticResult, EngineResult, calibrate_elastic, order_blocks, pose_blocks
from ..elastic import run_engine
from ..identify import CalibrationOptions, calibrate, whitening
from ..kinematics import ParamLayout, identification_jacobian, smr_tracker
from ..model import CalibratedModel
from .evidence import joints_following_order
from .findings import accepted_findings, other_findings
from .prose import DRIFT_EXPERIMENT
from .leftover import leftover, where_stages
from .records import Diagnosis, DiagnosisInput, DiagnosisOptions


@dataclass(frozen=True, eq=False)
class FittedStage:
    """The engine's answer computed by the caller (``campaign``: the elastic stage of reprocess, so both commands
    agree): ``engine`` (selection), ``elastic`` (the final joint fit or None), ``fit_rows`` (indices of the input
    rows it was fitted on) and ``meta`` (the effects' metadata of every input row)."""
    engine: EngineResult
    elastic: ElasticResult | None
    fit_rows: np.ndarray
    meta: dict


def _sub(meta: dict, rows) -> dict:
    return {k: (None if v is None else np.asarray(v)[rows]) for k, v in meta.items()}


def _baseline(inp: DiagnosisInput):
    """(geometric kinematics, identified columns): the given baseline or an LM fit of the calibration rows."""
    if inp.baseline is not None and inp.baseline_identified is not None:
        layout = ParamLayout.of(inp.baseline)
        return inp.baseline, np.array([layout.index(n) for n in inp.baseline_identified], int)
    cal = np.flatnonzero(inp.calib)
    res = calibrate(inp.kin, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], CalibrationOptions(method="lm"))
    layout = ParamLayout.of(res.kinematics)
    return res.kinematics, np.array([layout.index(n) for n in res.identified], int)


def _own_stage(inp, opt, kin_geo, cols, meta) -> FittedStage:
    """Arrays without a caller's stage: gross outliers (> ``outlier_sigma`` robust sigma of the geometric fit,
    fewer than 10 % of the rows) set aside, then the engine on the calibration rows."""
    cal = np.flatnonzero(inp.calib)
    r = inp.p_mm[cal] - smr_tracker(kin_geo, inp.q_rad[cal])
    W = whitening(inp.cov_mm2[cal], len(cal))
    d = np.linalg.norm(np.einsum("nij,nj->ni", W, r), axis=1) / math.sqrt(3.0)
    s = 1.4826 * np.median(d)
    bad = d > opt.outlier_sigma * max(s, 1e-12)
    fit = cal[~bad] if bad.sum() < 0.1 * len(cal) else cal
    eng = run_engine(kin_geo, cols, inp.q_rad[fit], inp.p_mm[fit], inp.cov_mm2[fit], _sub(meta, fit), inp.gravity,
                     opt.engine)
    return FittedStage(eng, eng.elastic, fit, meta)


def _rms(r) -> float:
    return float(np.sqrt(np.mean(np.sum(np.asarray(r).reshape(-1, 3) ** 2, axis=1)))) if len(r) else float("nan")


def diagnose(inp: DiagnosisInput, options: DiagnosisOptions = DiagnosisOptions(),
             stage: FittedStage | None = None) -> Diagnosis:
    """The whole diagnosis of one dataset (see the module docstring); ``stage``: the engine's answer when the
    caller already has it (else it is computed here on the calibration rows)."""
    opt = options
    q, p = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float)
    kin_geo, cols = _baseline(inp)
    meta = inp.meta() if stage is None else stage.meta
    stage = _own_stage(inp, opt, kin_geo, cols, meta) if stage is None else stage
    fit, test = np.asarray(stage.fit_rows, int), np.flatnonzero(inp.test)
    engine, elastic = stage.engine, stage.elastic
    effects = () if elastic is None else elastic.effects
    m_fit = _sub(meta, fit)
    n = kin_geo.n
    # ---- step by step: the taken effects added one at a time (the last step is the engine's final fit)
    models = [CalibratedModel(kin_geo)]
    for k in range(1, len(effects)):
        el = calibrate_elastic(kin_geo, cols, q[fit], p[fit], inp.cov_mm2[fit], m_fit, [fe.choice for fe in effects[:k]])
        models.append(CalibratedModel(el.kinematics, None, None, el.effects))
    if elastic is not None:
        models.append(CalibratedModel(elastic.kinematics, None, None, elastic.effects))
    resid = [p - m.smr_tracker(q, meta) for m in models]
    # ---- linearised design of the fit rows (held-out residuals, consistency, confounds)
    p0, J = identification_jacobian(kin_geo, q[fit])
    R = [effect_regressor(kin_geo, q[fit], m_fit, fe.choice.build(n), jacobian=(p0, J)) for fe in effects]
    A = np.concatenate([J[:, :, cols]] + R, axis=2)
    blockings = [Blocking("pose blocks", pose_blocks(q[fit], opt.engine.folds, opt.engine.seed))]
    if m_fit.get("order") is not None:
        blockings.append(Blocking("order blocks", order_blocks(m_fit["order"], opt.engine.folds)))
    cv = BlockedCV(A, p[fit] - p0, whitening(inp.cov_mm2[fit], len(fit)), blockings)
    geo_cols = np.arange(len(cols))
    eff_cols, at = [], len(cols)
    for fe in effects:
        eff_cols.append(np.arange(at, at + fe.values.size))
        at += fe.values.size
    prefix = [np.concatenate([geo_cols] + eff_cols[:k]) for k in range(len(models))]
    cv_vec = [cv.errors(c) for c in prefix]
    cv_steps = [math.sqrt(float(np.mean(np.mean(np.stack(list(cv.squared_errors(c).values())), axis=0))))
                for c in prefix]               # mean over the blockings, as the engine's selection
    evaluation = "test" if len(test) else "cv"
    key = "test_rms_mm" if evaluation == "test" else "cv_rms_mm"
    sel = engine.selection
    stages = []
    for k, (m, r) in enumerate(zip(models, resid)):
        stages.append({"added": "geometric model" if k == 0 else effects[k - 1].choice.label,
                       "effects": [fe.choice.label for fe in effects[:k]], "test_rms_mm": _rms(r[test]),
                       "cv_rms_mm": cv_steps[k], "calib_rms_mm": _rms(r[fit]),
                       "n_params": len(cols) + sum(fe.values.size for fe in effects[:k])})
    T = kin_geo.T_tracker_base
    pb = (p0 - T[:3, 3]) @ T[:3, :3]
    reach = np.hypot(pb[:, 0], pb[:, 1])
    halves = {"near and far reach": reach < np.median(reach)}
    if m_fit.get("order") is not None:
        o = np.asarray(m_fit["order"], float)
        halves["the first and second half of the run"] = o < np.median(o)
    ctx = {"floor": inp.noise_floor_mm, "n": n, "kin": models[-1].kinematics, "kin_geo": kin_geo, "q": q[fit], "meta": m_fit,
           "gravity": inp.gravity, "R": R, "J_geo": J[:, :, cols], "A_w": cv.Aw, "y_w": cv.yw, "cols": eff_cols,
           "geo_cols": geo_cols, "halves": halves}
    findings = accepted_findings(engine, effects, stages, key, ctx, opt)
    others, cannot = other_findings(engine, stages[-1][key], opt, n)
    order = meta.get("order")
    follow = [] if order is None else joints_following_order(q[fit], np.asarray(order)[fit], opt.confound_r)
    if follow:                 # a property of the data, whatever was accepted
        js = ", ".join(f"J{j} (r = {r:+.2f})" for j, r in follow)
        cannot.append({"effect": "registration_drift", "joints": [j for j, _ in follow], "remedy": DRIFT_EXPERIMENT,
                       "reason": f"{js} follow{'s' if len(follow) == 1 else ''} the measurement order: a drift in time "
                                 f"and an effect of {'that joint' if len(follow) == 1 else 'those joints'} cannot be "
                                 "told apart in these data (one confounded class)"})
    where, maps = where_stages(inp, opt, fit, test, (kin_geo, models[-1]), (resid[0], resid[-1]),
                               (cv_vec[0], cv_vec[-1]), (stages[0], stages[-1]), meta)
    unexplained, structure, notes = leftover(inp, opt, fit, test, models[-1], resid[-1], cv_vec[-1], stages[-1],
                                             blockings[0].fold, meta)
    for f in findings:
        for k in ("description", "consistency_note"):
            if k in f.evidence:
                notes.append(f"{f.evidence['label']}: {f.evidence[k]}")
        if "order_confound" in f.evidence:
            c = f.evidence["order_confound"]
            notes.append(f"{c['text']}; to separate them: {c['experiment']}")
    if unexplained["unexplained"]:
        where += [r for r in maps.pop("_final_regions") if r.kind != "all"]
    else:
        maps.pop("_final_regions")
    outliers = tuple(int(i) for i in np.setdiff1d(np.flatnonzero(inp.calib), fit))
    return Diagnosis(float(inp.noise_floor_mm), inp.noise_floor_source, stages[0][key], stages[-1][key],
                     unexplained["unexplained"], tuple(findings + others), tuple(where), tuple(cannot), evaluation,
                     unexplained, structure, maps, tuple(notes), int(inp.calib.sum()), len(test), outliers,
                     models[-1].kinematics, tuple(effects), tuple(stages), sel.to_dict())
