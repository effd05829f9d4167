"""The model an adaptive selection refits after every batch, and its uncertainty as the selection sees it.

``refit`` fits the measured rows as ``reprocess`` does (preparation, fault screen, geometry, the effect engine,
the residual layer chosen by CV: ``campaign.calibrate.stages``). ``design_terms`` describes that model's
uncertainty to ``robocal.design.adaptive``: the parametric part (identified geometry + the effects taken, linearised at the
fit, whitened by the calibration weights, variance scaled by the fit's unit-weight error s0^2) and the residual
layer (the joint GP's own features and prior; the GPR's kernel; without a GP layer, a GP fitted to the parametric
model's residuals, whose signal is small where the data show no structure).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.design.adaptive import Batch, KernelTerm, LinearTerm
from robocal.design.optimal import whiten_rows
from robocal.identify import geometric_prior_sigma
from robocal.effects.bases import effect_regressor
from robocal.layers.gp import MultiOutputGP
from robocal.layers.gp_layer import GPRResidual, gp_inputs
from robocal.layers.joint_gp import JointGPResidual
from robocal.kinematics.models import ParamLayout, identification_jacobian
from robocal.layers.choice import layer_targets

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset

from .effects_stage import subset
from .plausibility import check_dataset
from .stages import final_layer, fit_stages

MAX_TASK_ROWS = 400             # the task poses the variance is averaged over (a seeded sample beyond)


@dataclass(frozen=True, eq=False)
class CurrentModel:
    """The fit of the rows measured so far: kinematics with the identified geometric columns ``cols`` and the
    effects taken (built), the rows fitted (joints rad, metadata, covariances mm^2, parametric residuals mm in
    the base frame), s0, the chosen layer (``LayerChoice``), the noise floor and the held-out RMS that the layer
    choice's k-fold CV gives the final model (mm)."""
    kinematics: object
    cols: np.ndarray
    effects: tuple
    q_rad: np.ndarray
    meta: dict
    cov_mm2: np.ndarray
    residual_base_mm: np.ndarray
    s0: float
    layer: object
    floor_mm: float
    cv_rms_mm: float

    @property
    def layer_kind(self) -> str:
        return self.layer.kind


def refit(ds: Dataset, cell: CellModel, *, force: bool = False) -> CurrentModel:
    """The model ``reprocess`` would fit to ``ds`` (its calibration rows; test rows are never needed; the nest rows
    once every nest has been read twice: before, no drift can be told from them)."""
    if ds.nest_id is not None and ds.mask("nest").any():
        ids = np.array(ds.nest_id)[ds.mask("nest")]
        if min(np.unique(ids, return_counts=True)[1]) < 2:
            ds = ds.subset(~ds.mask("nest"))
    ds, plaus = check_dataset(ds, cell, force=force)
    fitted = fit_stages(ds, cell, plaus)
    stage = fitted.stage
    fl = final_layer(fitted.dataset, cell, stage)
    data = fitted.dataset
    kept = stage.kept_rows
    q, p = np.radians(data.q_deg[kept]), data.p_tracker_mm[kept]
    meta = subset(stage.meta, kept)
    cov = cell.weights(data)[0][kept]
    model = fl.base                                        # the elastic model, or the geometry when it won
    kin = model.kinematics
    layout = ParamLayout.of(kin)
    cols = np.array([layout.index(n) for n in fitted.geo.result.identified], int)
    effects = tuple(fe.choice.build(kin.n) for fe in model.effects)
    _, _, e_base = layer_targets(model, q, p, meta)
    J = parametric_columns(kin, cols, effects, q, meta)
    r_w = whiten_rows((p - model.smr_tracker(q, meta))[:, :, None], cov)[:, :, 0]
    s0 = float(np.sqrt(np.sum(r_w**2) / max(r_w.size - J.shape[2], 1)))
    cv_rms = fl.choice.cv_rms_mm
    cv_rms = fl.choice.cv.get("none", {}).get("cv_rms_mm") if cv_rms is None else cv_rms
    if cv_rms is None:                                     # no CV (too few rows): the fit's RMS, inflated by its dof
        cv_rms = float(np.sqrt(np.sum(e_base**2) / max(len(q) - J.shape[2] / 3.0, 1.0)))
    return CurrentModel(kin, cols, effects, q, meta, cov, e_base, s0, fl.choice, float(fl.floor_mm), float(cv_rms))


def parametric_columns(kin, cols: np.ndarray, effects, q_rad: np.ndarray, meta: dict) -> np.ndarray:
    """(N, 3, P) mm per unit parameter: the identified geometric columns and the effects' regressors at q (N, n)."""
    p, J = identification_jacobian(kin, q_rad)
    regs = [effect_regressor(kin, q_rad, meta, e, jacobian=(p, J)) for e in effects]
    return np.concatenate([J[:, :, cols]] + regs, axis=2)


def _prior_std(cur: CurrentModel) -> np.ndarray:
    layout = ParamLayout.of(cur.kinematics)
    geo = geometric_prior_sigma([layout.unit(layout.names[c]) for c in cur.cols])
    return np.concatenate([geo] + [np.asarray(e.typical, float) for e in cur.effects])


def task_sample(n: int, seed: int = 0) -> np.ndarray:
    """Indices of at most ``MAX_TASK_ROWS`` of n task poses (seeded, sorted)."""
    if n <= MAX_TASK_ROWS:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, MAX_TASK_ROWS, replace=False))


def design_terms(cur: CurrentModel, q_cand: np.ndarray, meta_cand: dict, cov_cand: np.ndarray,
                 q_task: np.ndarray, meta_task: dict | None = None) -> list:
    """``robocal.design.adaptive`` terms of the current model over candidates q_cand (M, n) rad (their effect metadata
    and covariances (M, 3, 3) mm^2), judged at the task poses q_task (T, n): [parametric, layer]. The parametric
    variance is scaled by the noise the layer leaves (per axis, over the noise model's), between 1 and s0^2: the
    structure the layer describes is not noise of the parametric fit."""
    layer, noise2 = _layer_term(cur, q_cand, meta_cand, q_task, meta_task)
    model2 = float(np.mean(np.trace(cur.cov_mm2, axis1=1, axis2=2))) / 3.0
    scale = float(np.clip(noise2 / model2, 1.0, max(cur.s0**2, 1.0)))
    prior = _prior_std(cur)
    A = lambda q, meta, cov: whiten_rows(parametric_columns(cur.kinematics, cur.cols, cur.effects, q, meta),  # noqa: E731
                                         cov) * prior
    B_task = parametric_columns(cur.kinematics, cur.cols, cur.effects, q_task, meta_task or {}) * prior
    return [LinearTerm(A(q_cand, meta_cand, cov_cand), A(cur.q_rad, cur.meta, cur.cov_mm2), B_task, scale), layer]


def _layer_term(cur: CurrentModel, q_cand, meta_cand, q_task, meta_task):
    """(the layer's term, its noise variance per axis mm^2): the joint GP's features and prior, the GPR's kernel, or
    without a GP layer a GP of the parametric residuals."""
    layer = cur.layer.layer
    if isinstance(layer, JointGPResidual):
        w = layer.prior_std() / layer.noise_mm
        return LinearTerm(layer.features(q_cand) * w, layer.features(cur.q_rad) * w,
                          layer.features(q_task) * layer.prior_std()), layer.noise_mm**2
    gp = layer.gp if isinstance(layer, GPRResidual) and isinstance(layer.gp, MultiOutputGP) else None
    pay = None
    if gp is None:                                         # no GP layer: a GP of the parametric residuals
        gp = MultiOutputGP.fit_subset(cur.q_rad, cur.residual_base_mm, noise_floor_mm=cur.floor_mm)
    elif layer.uses_payload:
        pay = lambda meta, n: np.broadcast_to(np.asarray((meta or {}).get("payload_kg", 0.0), float), (n,))  # noqa: E731
    x = lambda q, meta: gp_inputs(q, None if pay is None else pay(meta, len(q))) / gp.models[0].length  # noqa: E731
    g0 = gp.models[0]
    signal = float(sum(g.sigma_f**2 for g in gp.models))
    term = KernelTerm(x(q_cand, meta_cand), g0.X / g0.length, x(q_task, meta_task), signal, (g0.sigma_n / g0.sigma_f) ** 2)
    return term, float(np.mean([g.sigma_n**2 for g in gp.models]))


def predicted_curve(cur: CurrentModel, batch: Batch, n: int) -> tuple[tuple[int, float], ...]:
    """((n + j, mm), ...) for j = 0 .. len(batch): the predicted held-out RMS now (the larger of the refit's CV
    figure and the noise floor with the model's own prediction variance at the task poses) and after each pick of
    the batch (that less the variance the picks remove), never below the floor."""
    v = batch.task_variance_mm2
    now2 = max(cur.cv_rms_mm**2, cur.floor_mm**2 + v[0])
    return tuple((n + j, float(np.sqrt(max(now2 - (v[0] - x), cur.floor_mm**2)))) for j, x in enumerate(v))
