"""``diagnose``: the effect engine's answer on one dataset, and what only the diagnosis adds to it.

The engine (``robocal.effects``) decides which effects the data support and fits them with the geometry; the
calibration (``campaign reprocess``) uses the same answer. The diagnosis adds: how far each effect shrinks the
error on held-out points (step by step), where the residual lies (``regions``), confusable classes and the
experiment that separates them, confounds with the measurement order, consistency of each effect's parameters,
what the data cannot tell, and the unexplained structure (one definition, ``unexplained_structure``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.effects.cv import BlockedCV, Blocking, capped_rows, order_blocks, pose_blocks
from robocal.effects.fit import ElasticResult, calibrate_elastic
from robocal.effects.engine import EngineResult
from robocal.effects.engine import run_engine
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.identify.whitened import whitening
from robocal.kinematics.models import ParamLayout, smr_tracker
from robocal.layers.calibrated_model import CalibratedModel
from .evidence import joints_following_order
from .findings import accepted_findings, other_findings
from .prose import DRIFT_EXPERIMENT
from .budget import linear_design
from .gap import budget_and_verdict
from .next_steps import next_steps
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


def _step_models(kin_geo, cols, q, p, cov, meta, effects, elastic) -> list[CalibratedModel]:
    """The geometric model, then the taken effects added one at a time (exact joint fits of the prefixes on the
    rows given; the last is the engine's own fit)."""
    models = [CalibratedModel(kin_geo)]
    for k in range(1, len(effects)):
        el = calibrate_elastic(kin_geo, cols, q, p, cov, meta, [fe.choice for fe in effects[:k]])
        models.append(CalibratedModel(el.kinematics, None, None, el.effects))
    if elastic is not None:
        models.append(CalibratedModel(elastic.kinematics, None, None, elastic.effects))
    return models


def _linear_design(kin_geo, cols, q, p, cov, meta, effects, opt):
    """Blocked CV of the linearised design of the fit rows (geometry + the final effects) with the engine's
    blockings; the regressors (N, 3, K) per effect, the geometric Jacobian and the effects' column ranges."""
    p0, A, R, eff_cols = linear_design(kin_geo, cols, q, meta, effects)
    blockings = [Blocking("pose blocks", pose_blocks(q, opt.engine.folds, opt.engine.seed))]
    if meta.get("order") is not None:
        blockings.append(Blocking("order blocks", order_blocks(meta["order"], opt.engine.folds)))
    J_geo = np.array(A[:, :, :len(cols)])
    cv = BlockedCV(A, p - p0, whitening(cov, len(q)), blockings, copy=False)     # a fresh array: whitened in place
    del A
    return cv, R, J_geo, p0, eff_cols


def _stages(models, resid, cv, eff_cols, n_geo, fit, test, effects) -> list[dict]:
    """Test and cross-validated RMS (mean over the blockings, as the engine's selection) after each step."""
    out = []
    for k, (m, r) in enumerate(zip(models, resid)):
        se = cv.squared_errors(np.concatenate([np.arange(n_geo)] + eff_cols[:k]))
        out.append({"added": "geometric model" if k == 0 else effects[k - 1].choice.label,
                    "effects": [fe.choice.label for fe in effects[:k]], "test_rms_mm": _rms(r[test]),
                    "cv_rms_mm": math.sqrt(float(np.mean(np.mean(np.stack(list(se.values())), axis=0)))),
                    "calib_rms_mm": _rms(r[fit]), "n_params": n_geo + sum(fe.values.size for fe in effects[:k])})
    return out


def _halves(kin_geo, p0, meta) -> dict[str, np.ndarray]:
    """Splits of the fit rows for the consistency evidence: near/far horizontal reach, first/second half."""
    T = kin_geo.T_tracker_base
    pb = (p0 - T[:3, 3]) @ T[:3, :3]
    reach = np.hypot(pb[:, 0], pb[:, 1])
    out = {"near and far reach": reach < np.median(reach)}
    if meta.get("order") is not None:
        o = np.asarray(meta["order"], float)
        out["the first and second half of the run"] = o < np.median(o)
    return out


def _order_cannot_tell(q, order, r_min) -> list[dict]:
    """Joints that follow the measurement order: a drift in time and their effects are one class (a property of
    the data, whatever was accepted)."""
    follow = [] if order is None else joints_following_order(q, order, r_min)
    if not follow:
        return []
    js = ", ".join(f"J{j} (r = {r:+.2f})" for j, r in follow)
    return [{"effect": "registration_drift", "joints": [j for j, _ in follow], "remedy": DRIFT_EXPERIMENT,
             "reason": f"{js} follow{'s' if len(follow) == 1 else ''} the measurement order: a drift in time and an "
                       f"effect of {'that joint' if len(follow) == 1 else 'those joints'} cannot be told apart in "
                       "these data (one confounded class)"}]


def diagnose(inp: DiagnosisInput, options: DiagnosisOptions = DiagnosisOptions(),
             stage: FittedStage | None = None) -> Diagnosis:
    """The whole diagnosis of one dataset (see the module docstring); ``stage``: the engine's answer when the
    caller already has it (else it is computed here on the calibration rows)."""
    opt = options
    q, p, cov = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float), np.asarray(inp.cov_mm2, float)
    kin_geo, cols = _baseline(inp)
    meta = inp.meta() if stage is None else stage.meta
    stage = _own_stage(inp, opt, kin_geo, cols, meta) if stage is None else stage
    fit_all, test_all = np.asarray(stage.fit_rows, int), np.flatnonzero(inp.test)
    fit_sub, test_sub = (capped_rows(len(rows), opt.engine.max_rows, opt.seed) for rows in (fit_all, test_all))
    fit, test = (rows if sub is None else rows[sub]          # the analyses: at most max_rows of each (a seeded subset)
                 for rows, sub in ((fit_all, fit_sub), (test_all, test_sub)))
    effects = () if stage.elastic is None else stage.elastic.effects
    m_fit = _sub(meta, fit)
    models = _step_models(kin_geo, cols, q[fit], p[fit], cov[fit], m_fit, effects, stage.elastic)
    resid = [p - m.smr_tracker(q, meta) for m in models]
    cv, R, J_geo, p0, eff_cols = _linear_design(kin_geo, cols, q[fit], p[fit], cov[fit], m_fit, effects, opt)
    evaluation = "test" if len(test_all) else "cv"
    key = "test_rms_mm" if evaluation == "test" else "cv_rms_mm"
    stages = _stages(models, resid, cv, eff_cols, len(cols), fit_all, test_all, effects)
    ctx = {"floor": inp.noise_floor_mm, "n": kin_geo.n, "kin": models[-1].kinematics, "kin_geo": kin_geo,
           "q": q[fit], "meta": m_fit, "gravity": inp.gravity, "R": R, "J_geo": J_geo, "A_w": cv.Aw, "y_w": cv.yw,
           "cols": eff_cols, "geo_cols": np.arange(len(cols)), "halves": _halves(kin_geo, p0, m_fit)}
    findings = accepted_findings(stage.engine, effects, stages, key, ctx, opt)
    others, cannot = other_findings(stage.engine, stages[-1][key], opt, kin_geo.n)
    cannot += _order_cannot_tell(q[fit], m_fit.get("order"), opt.confound_r)
    cv_vec = [cv.errors(np.concatenate([np.arange(len(cols))] + eff_cols[:k])) for k in (0, len(effects))]
    where, maps = where_stages(inp, opt, fit, test, (kin_geo, models[-1]), (resid[0], resid[-1]), cv_vec,
                               (stages[0], stages[-1]), meta)
    unexplained, structure, notes, rem, held_err = leftover(inp, opt, fit, test_all, models[-1], resid[-1],
                                                          cv_vec[-1], stages[-1], cv.blockings[0].fold, meta)
    if len(test) < len(test_all):        # the budget's analyses: the held-out errors of the test subset
        held_err = {k: v[test_sub] for k, v in held_err.items()}
    for f in findings:
        notes += [f"{f.evidence['label']}: {f.evidence[k]}" for k in ("description", "consistency_note")
                  if k in f.evidence]
        if "order_confound" in f.evidence:
            notes.append(f"{f.evidence['order_confound']['text']}; to separate them: "
                         f"{f.evidence['order_confound']['experiment']}")
    final_regions = maps.pop("_final_regions")
    gap = budget_and_verdict(inp, opt, (kin_geo, cols, fit, test, meta), (models[0], models[-1]), resid, cv,
                             eff_cols, effects, findings, held_err, rem, unexplained, (stages[0], stages[-1]))
    if gap.nonphysical:
        notes.append(gap.verdict_text)
    if unexplained["unexplained"]:
        where += gap.ranked or [r for r in final_regions if r.kind != "all"]
    outliers = tuple(int(i) for i in np.setdiff1d(np.flatnonzero(inp.calib), fit_all))
    return Diagnosis(float(inp.noise_floor_mm), inp.noise_floor_source, stages[0][key], stages[-1][key],
                     unexplained["unexplained"], tuple(findings + others), tuple(where), tuple(cannot), evaluation,
                     unexplained, structure, maps, tuple(notes), int(inp.calib.sum()), len(test_all), outliers,
                     models[-1].kinematics, tuple(effects), tuple(stages), stage.engine.selection.to_dict(),
                     gap.budget, gap.remainder, gap.layer,
                     tuple(next_steps(gap.budget, gap.remainder, findings, unexplained, gap.layer, cannot)))
