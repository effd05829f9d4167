"""The model an adaptive selection refits after every batch, and its uncertainty as the selection sees it.

``refit`` fits the measured rows as ``reprocess`` does (preparation, fault screen, geometry, the effect engine,
the residual layer chosen by CV: ``campaign.calibrate.stages``). ``design_terms`` describes that model's
uncertainty to ``robocal.adaptive``: the parametric part (identified geometry + the effects taken, linearised at the
fit, whitened by the calibration weights, variance scaled by the fit's unit-weight error s0^2) and the residual
layer (the joint GP's own features and prior; the GPR's kernel; without a GP layer, a GP fitted to the parametric
model's residuals, whose signal is small where the data show no structure).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.adaptive import KernelTerm, LinearTerm
from robocal.design import geometric_prior_sigma, whiten_rows
from robocal.effects import effect_regressor
from robocal.gp import MultiOutputGP
from robocal.gp_layer import GPRResidual, gp_inputs
from robocal.joint_gp import JointGPResidual
from robocal.kinematics import ParamLayout, identification_jacobian
from robocal.layers import layer_targets

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


def refit(ds: Dataset, cell: CellModel) -> CurrentModel:
    """The model ``reprocess`` would fit to ``ds`` (its calibration rows; test rows are never needed)."""
    ds, plaus = check_dataset(ds, cell)
    fitted = fit_stages(ds, cell, plaus)
    stage = fitted.stage
    fl = final_layer(fitted.dataset, cell, stage)
    data = fitted.dataset
    kept = stage.kept_rows
    q, p = np.radians(data.q_deg[kept]), data.p_tracker_mm[kept]
    meta = subset(stage.meta, kept)
    cov = cell.weights(data)[0][kept]
    model = stage.model
    kin = model.kinematics
    layout = ParamLayout.of(kin)
    cols = np.array([layout.index(n) for n in fitted.geo.result.identified], int)
    effects = tuple(fe.choice.build(kin.n) for fe in model.effects)
    _, _, e_base = layer_targets(model, q, p, meta)
    J = parametric_columns(kin, cols, effects, q, meta)
    r_w = whiten_rows((p - model.smr_tracker(q, meta))[:, :, None], cov)[:, :, 0]
    s0 = float(np.sqrt(np.sum(r_w**2) / max(r_w.size - J.shape[2], 1)))
    cv = fl.choice.cv
    cv_rms = cv.get(fl.choice.kind, cv.get("none", {})).get("cv_rms_mm")
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
    """``robocal.adaptive`` terms of the current model over candidates q_cand (M, n) rad (their effect metadata
    and covariances (M, 3, 3) mm^2), judged at the task poses q_task (T, n)."""
    prior = _prior_std(cur)
    A = lambda q, meta, cov: whiten_rows(parametric_columns(cur.kinematics, cur.cols, cur.effects, q, meta),  # noqa: E731
                                         cov) * prior
    B_task = parametric_columns(cur.kinematics, cur.cols, cur.effects, q_task, meta_task or {}) * prior
    terms = [LinearTerm(A(q_cand, meta_cand, cov_cand), A(cur.q_rad, cur.meta, cur.cov_mm2), B_task, cur.s0**2)]
    layer = cur.layer.layer
    if isinstance(layer, JointGPResidual):
        w = layer.prior_std()
        terms.append(LinearTerm(layer.features(q_cand) * (w / layer.noise_mm), layer.features(cur.q_rad) *
                                (w / layer.noise_mm), layer.features(q_task) * w))
        return terms
    gp = layer.gp if isinstance(layer, GPRResidual) and isinstance(layer.gp, MultiOutputGP) else None
    pay = None
    if gp is None:                                         # no GP layer: a GP of the parametric residuals
        gp = MultiOutputGP.fit_subset(cur.q_rad, cur.residual_base_mm, noise_floor_mm=cur.floor_mm)
    elif layer.uses_payload:
        pay = lambda meta, n: np.broadcast_to(np.asarray((meta or {}).get("payload_kg", 0.0), float), (n,))  # noqa: E731
    x = lambda q, meta: gp_inputs(q, None if pay is None else pay(meta, len(q))) / gp.models[0].length  # noqa: E731
    g0 = gp.models[0]
    signal = float(sum(g.sigma_f**2 for g in gp.models))
    terms.append(KernelTerm(x(q_cand, meta_cand), g0.X / g0.length, x(q_task, meta_task), signal,
                            (g0.sigma_n / g0.sigma_f) ** 2))
    return terms
