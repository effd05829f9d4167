"""Residual layers on top of a calibrated model, fitted and chosen by cross-validation.

``layer_targets`` gives, for calibration points, the measured SMR positions and the residuals measured - model in
the robot base frame (kinematic layer with its physical effects). ``fit_layer`` fits an IDW (seed 000), GPR
(seed 003), joint-error GP (``robocal.layers.joint_gp``: one angle-error curve per joint) or trend + GPR
(``robocal.layers.trend``: a quadratic trend with a linearised change of the geometry) layer on them.
``choose_layer`` compares none / IDW / GPR / joint GP / trend + GPR by k-fold CV on the calibration points (the
kinematic layer fixed) and keeps a layer when its CV gain over none passes the one-standard-error rule (one-sided
paired t of the per-point squared errors > 1 and CV RMS lower by > 2 %, ``robocal.measure.stats.paired_gain``): the layer
is chosen for prediction and claims no cause, so the stricter test of a claim (t > 3) is only reported. With a
few hundred points or fewer the strict test dropped layers that predicted real structure. GPR's CV re-fits the
hyperparameters on every training fold (hyperparameters fitted on the held-out points too make a GP that
interpolates noise look useful). The GPR is exact up to ``EXACT_MAX_POINTS`` training points and the inducing-point
approximation above (``robocal.layers.sparse_gp``: bounded memory); the CV evaluates the one that is then used. Its noise is
bounded below by the measurement noise floor (``noise_floor_mm``, 3-D RMS) when one is given. IDW queries a KD-tree.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from robocal.effects.bases import meta_rows
from robocal.effects.cv import CV_MAX_ROWS, capped_rows, kfold
from .gp_layer import GPRResidual, gp_inputs
from .gp import MultiOutputGP
from .joint_gp import JointGPResidual, fit_joint_gp
from .calibrated_model import CalibratedModel
from .idw import IDWResidual
from .sparse_gp import EXACT_MAX_POINTS, SparseGP
from .trend import TREND_MAX_ROWS, TrendGPRResidual, fit_trend_gpr
from robocal.measure.stats import paired_gain

LAYER_KINDS = ("idw", "gpr", "joint_gp", "trend_gpr")
GEOMETRIC_RIVAL = True      # offer the geometric model with a trend + GPR layer against the effects (issue 32's 13th)


def layer_targets(model: CalibratedModel, q_rad: np.ndarray, p_tracker_mm: np.ndarray, meta: Mapping | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(p_kin_base (N, 3), p_meas_base (N, 3), e_base (N, 3)) mm: model (no layer), measured, and their difference
    in the robot base frame."""
    T = model.kinematics.T_tracker_base
    p_meas = (np.asarray(p_tracker_mm, float) - T[:3, 3]) @ T[:3, :3]
    p_kin = model.kinematic_smr_base(q_rad, meta)
    return p_kin, p_meas, p_meas - p_kin


def identified_geometry(model: CalibratedModel) -> dict:
    """``fit_trend_gpr``'s geometry keywords: the model's kinematics and the names of its identified geometric
    parameters (none when the model carries no parameter table)."""
    table = model.parameters
    names = () if table is None else tuple(r.name for r in table.rows if r.identified)
    return {"kinematics": model.kinematics, "names": names}


def fit_gp(X: np.ndarray, Y: np.ndarray, seed: int = 0, noise_floor_mm: float | None = None):
    """The layer's GP of inputs X (N, d) and residuals Y (N, 3) mm: exact (``MultiOutputGP.fit_subset``) up to
    ``EXACT_MAX_POINTS`` points, the inducing-point ``SparseGP`` above; noise bounded below by the floor."""
    if len(X) <= EXACT_MAX_POINTS:
        return MultiOutputGP.fit_subset(X, Y, seed=seed, noise_floor_mm=noise_floor_mm)
    return SparseGP.fit(X, Y, seed=seed, noise_floor_mm=noise_floor_mm)


def gp_cv_errors(gp, X: np.ndarray, Y: np.ndarray, fold: np.ndarray, seed: int = 0) -> np.ndarray:
    """k-fold held-out errors (N, 3) mm of a ``fit_gp`` model fitted on X, Y (hyperparameters re-fitted per fold)."""
    if isinstance(gp, SparseGP):
        return gp.cv_errors(X, Y, fold, seed=seed)
    return gp.cv_errors(fold, seed=seed)


def fit_layer(kind: str, model: CalibratedModel, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
              meta: Mapping | None = None, payload_kg: np.ndarray | None = None, idw_power: float = 2.0,
              idw_k_nearest: int = 8, seed: int = 0, noise_floor_mm: float | None = None):
    """A layer of ``kind`` on the calibration residuals of ``model`` (payload_kg (N,) as a GPR input when given;
    ``noise_floor_mm`` bounds the GPR's noise below)."""
    p_kin, p_meas, e = layer_targets(model, q_rad, p_tracker_mm, meta)
    if kind == "idw":
        return IDWResidual.fit(p_meas, e, idw_power, idw_k_nearest)
    if kind == "gpr":
        gp = fit_gp(gp_inputs(q_rad, payload_kg), e, seed, noise_floor_mm)
        return GPRResidual(gp, payload_kg is not None, None)
    if kind == "joint_gp":
        return fit_joint_gp(model.kinematics, q_rad, e, noise_floor_mm)[0]
    if kind == "trend_gpr":
        return fit_trend_gpr(q_rad, p_kin, e, payload_kg, seed, noise_floor_mm, **identified_geometry(model))[0]
    raise ValueError(f"unknown residual layer {kind!r} (expected one of: {', '.join(LAYER_KINDS)})")


@dataclass(frozen=True)
class WithoutEffects:
    """The geometric model with a trend + GPR layer against the model with its physical effects ``effects``
    (labels) and its best candidate ``against`` (a layer kind or "none"): both CV RMS (mm), the gain, the paired t
    and whether the final model leaves the effects out (``chosen``: the one-standard-error rule passed); and the
    layer against the geometric model without it (``geometry_cv_rms_mm``, its paired t ``geometry_t``, whether that
    gain is significant)."""
    effects: tuple[str, ...]
    against: str
    cv_rms_with_effects_mm: float
    cv_rms_mm: float
    gain: float
    t: float
    chosen: bool
    geometry_cv_rms_mm: float
    geometry_t: float
    geometry_significant: bool
    layer: str = "trend_gpr"

    def to_dict(self) -> dict:
        return {"effects": list(self.effects), "layer": self.layer, "against": self.against,
                "cv_rms_with_effects_mm": self.cv_rms_with_effects_mm, "cv_rms_mm": self.cv_rms_mm,
                "gain": self.gain, "t": self.t, "chosen": self.chosen, "geometry_cv_rms_mm": self.geometry_cv_rms_mm,
                "geometry_t": self.geometry_t, "geometry_significant": self.geometry_significant}


@dataclass(frozen=True, eq=False)
class LayerChoice:
    """The outcome of the CV comparison: chosen kind (or "none"), the fitted layer (or None) and, per candidate,
    its CV RMS (mm) and test against none; ``without_effects`` the comparison with the geometric model when it
    was offered (its ``chosen``: the layer sits on the geometric model, the effects left out)."""
    kind: str
    layer: object
    cv: dict
    folds: int
    rows: tuple[int, int] = (0, 0)      # (rows cross-validated and fitted, calibration rows): a seeded subset if fewer
    without_effects: WithoutEffects | None = None

    @property
    def on_geometry(self) -> bool:
        """The layer sits on the geometric model: the physical effects are left out of the final model."""
        return self.without_effects is not None and self.without_effects.chosen

    @property
    def cv_rms_mm(self) -> float | None:
        """The chosen candidate's CV RMS (mm; "none": the model without a layer), None when it was not
        cross-validated."""
        if self.on_geometry:
            return self.without_effects.cv_rms_mm
        return self.cv.get(self.kind, {}).get("cv_rms_mm")

    def to_dict(self) -> dict:
        sub = self.rows[0] < self.rows[1]
        rival = {} if self.without_effects is None else {"without_effects": self.without_effects.to_dict()}
        return {"chosen": self.kind, "folds": self.folds,
                "test": "one-standard-error rule: one-sided paired t of per-point held-out squared errors vs none > 1 "
                        "and CV RMS gain > 2 % ('significant': the same with t > 3)",
                "candidates": self.cv, **({"rows": self.rows[0], "of_rows": self.rows[1]} if sub else {}), **rival}


def cv_squared_errors(kind: str, model: CalibratedModel, q_rad, p_tracker_mm, fold, meta=None, payload_kg=None,
                      idw_power: float = 2.0, idw_k_nearest: int = 8, seed: int = 0,
                      noise_floor_mm: float | None = None):
    """(per-point held-out squared errors (N,) mm^2, layer fitted on all points or None) of one candidate."""
    p_kin, p_meas, e = layer_targets(model, q_rad, p_tracker_mm, meta)
    if kind == "none":
        return np.sum(e**2, axis=1), None
    if kind == "idw":
        err = np.empty_like(e)
        for k in np.unique(fold):
            tr, te = fold != k, fold == k
            lay = IDWResidual.fit(p_meas[tr], e[tr], idw_power, idw_k_nearest)
            err[te] = e[te] - lay.predict(None, p_kin[te])
        return np.sum(err**2, axis=1), IDWResidual.fit(p_meas, e, idw_power, idw_k_nearest)
    if kind == "gpr":
        X = gp_inputs(q_rad, payload_kg)
        gp = fit_gp(X, e, seed, noise_floor_mm)
        return np.sum(gp_cv_errors(gp, X, e, fold, seed) ** 2, axis=1), GPRResidual(gp, payload_kg is not None, None)
    if kind == "joint_gp":
        layer, err = fit_joint_gp(model.kinematics, q_rad, e, noise_floor_mm, fold)
        return (np.sum(e**2, axis=1), None) if layer is None else (np.sum(err**2, axis=1), layer)
    if kind == "trend_gpr":
        layer, err = fit_trend_gpr(q_rad, p_kin, e, payload_kg, seed, noise_floor_mm, fold,
                                   **identified_geometry(model))
        return np.sum(err**2, axis=1), layer
    raise ValueError(f"unknown residual layer {kind!r}")


def choose_layer(model: CalibratedModel, q_rad: np.ndarray, p_tracker_mm: np.ndarray, meta: Mapping | None = None,
                 payload_kg: np.ndarray | None = None, candidates=None, folds: int = 5, seed: int = 0,
                 idw_power: float = 2.0, idw_k_nearest: int = 8, noise_floor_mm: float | None = None,
                 max_rows: int = CV_MAX_ROWS, geometric: CalibratedModel | None = None) -> LayerChoice:
    """none / IDW / GPR / joint GP / trend + GPR (``candidates``, default ``LAYER_KINDS``) by k-fold CV on the calibration points:
    the candidate with the lowest CV RMS among those
    whose gain over none passes the one-standard-error rule, else none (``noise_floor_mm``: the GPR's noise
    bound). Each candidate's figures record also whether its gain is significant (t > 3). Beyond ``max_rows``
    points, a seeded subset of that many is cross-validated and the chosen layer fitted on it. ``geometric``: the
    model without its physical effects, whose trend + GPR layer (when among the candidates) then rivals the choice
    (module docstring)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    of_rows = len(q)
    sub = capped_rows(len(q), max_rows, seed)
    if sub is not None:
        q, p_tracker_mm = q[sub], np.asarray(p_tracker_mm)[sub]
        meta = None if meta is None else meta_rows(meta, sub)
        payload_kg = None if payload_kg is None else np.asarray(payload_kg)[sub]
    candidates = LAYER_KINDS if candidates is None else candidates
    if len(q) < 4 * folds:
        return LayerChoice("none", None, {}, folds, (len(q), of_rows))
    fold = kfold(len(q), folds, seed)
    kw = dict(meta=meta, payload_kg=payload_kg, idw_power=idw_power, idw_k_nearest=idw_k_nearest, seed=seed,
              noise_floor_mm=noise_floor_mm)
    se0, _ = cv_squared_errors("none", model, q, p_tracker_mm, fold, **kw)
    cv = {"none": {"cv_rms_mm": float(np.sqrt(np.mean(se0)))}}
    best = ("none", None, float(np.sqrt(np.mean(se0))), se0)
    for kind in candidates:
        if kind == "trend_gpr" and len(q) > TREND_MAX_ROWS:
            continue                                    # offered with few rows only (robocal.layers.trend)
        se, layer = cv_squared_errors(kind, model, q, p_tracker_mm, fold, **kw)
        g = paired_gain(se0, se)
        cv[kind] = {"cv_rms_mm": g.rms_cand_mm, "gain": g.gain, "t": g.t, "significant": g.significant,
                    "kept": g.beats_one_se}
        if g.beats_one_se and g.rms_cand_mm < best[2]:
            best = (kind, layer, g.rms_cand_mm, se)
    if not (GEOMETRIC_RIVAL and geometric is not None and model.effects and "trend_gpr" in candidates
            and len(q) <= TREND_MAX_ROWS):
        return LayerChoice(best[0], best[1], cv, folds, (len(q), of_rows))
    se, layer = cv_squared_errors("trend_gpr", geometric, q, p_tracker_mm, fold, **kw)
    g = paired_gain(best[3], se)
    g0 = paired_gain(cv_squared_errors("none", geometric, q, p_tracker_mm, fold, **kw)[0], se)
    rival = WithoutEffects(tuple(fe.choice.label for fe in model.effects), best[0], g.rms_base_mm, g.rms_cand_mm,
                           g.gain, g.t, bool(g.beats_one_se), g0.rms_base_mm, g0.t, bool(g0.significant))
    if rival.chosen:
        best = ("trend_gpr", layer)
    return LayerChoice(best[0], best[1], cv, folds, (len(q), of_rows), rival)


def layer_summary(choice: LayerChoice, stage: Mapping) -> dict:
    """The fitted layer next to its honest figures: ``calib_rms_mm`` of the final model on the calibration rows
    (a fit to points the layer has seen: not an accuracy), the CV-predicted held-out RMS (this layer's k-fold CV,
    the kinematic layer fixed) and the test-set RMS; for a GPR its approximation, training size and noise (3-D
    RMS, mm) against the floor it was bounded by. ``stage``: the report's compensated stage (calib/test stats)."""
    out = {"kind": choice.kind, "calib_rms_mm": stage["calib"]["rms_mm"],
           "cv_predicted_rms_mm": choice.cv_rms_mm, "folds": choice.folds,
           "test_rms_mm": stage["test"]["rms_mm"],
           "note": "calib_rms_mm is a fit to the points the layer interpolates, not an accuracy; "
                   "cv_predicted_rms_mm predicts the held-out RMS"}
    gp = getattr(choice.layer, "gp", None)
    if isinstance(choice.layer, JointGPResidual):
        lay = choice.layer
        arcsec = {f"J{j}": float(np.degrees(v) * 3600) for j, v in lay.curve_rms_rad().items()}
        out.update(approximation=lay.approximation, n_train=int(lay.n_train), n_inducing=None,
                   noise_mm=float(np.sqrt(3) * lay.noise_mm), noise_floor_mm=lay.noise_floor_mm,
                   joint_curve_rms_arcsec=arcsec)
    if isinstance(choice.layer, TrendGPRResidual):
        shift = choice.layer.shift
        out.update(trend_rms_mm=choice.layer.trend.fit_rms_mm,
                   **({} if shift is None else {"geometry_shift_rms_mm": shift.fit_rms_mm,
                                                "trend_and_shift_rms_mm": choice.layer.together_rms_mm}))
    if gp is not None:
        out.update(approximation=gp.kind, n_train=int(gp.n_train),
                   n_inducing=int(len(gp.Z)) if isinstance(gp, SparseGP) else None,
                   noise_mm=float(np.sqrt(np.sum(gp.sigma_n_mm**2))), noise_floor_mm=gp.noise_floor_mm)
    return out
