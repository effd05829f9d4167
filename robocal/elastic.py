"""Elasto-geometric calibration: physical effects as parameters of the calibrated model itself.

The effects of ``robocal.effects`` (joint compliance under gravity with payload, gear cyclic harmonics,
backlash, thermal scale, wrist axis coupling) act on the robot as joint-angle deviations ``dq`` and a relative
growth of the link lengths, linear in their parameters. Here they are

* identified jointly with the geometry (``calibrate_elastic``: Levenberg-Marquardt over the identified
  geometric parameters + the effect parameters, identifiability analysis over both),
* chosen by the data (``select_effects``: forward selection by k-fold cross-validation on the calibration
  points, an effect is taken only on a significant CV gain, see ``robocal.stats.paired_gain``),
* predicted exactly (``effect_state``): the model evaluates the chain at ``q + dq`` with scaled links.

Units: compliance c_j in rad/(N*m) (its stiffness 1/c_j in N*m/rad is reported too), harmonics in rad,
backlash in rad, thermal length growth per unit warm-up state, coupling dimensionless.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from .lm import levenberg_marquardt
from .effects import MODEL_EFFECTS, Effect, by_name, effect_regressor, gravity_torques, DEFAULT_LINK_MASSES_KG
from .identify import (CalibrationOptions, Unidentifiable, analyse_identifiability, whitening, _whiten)
from .kinematics import Kinematics, ParamLayout, apply_update, chain, identification_jacobian
from .frames import transform_points
from .stats import paired_gain



@dataclass(frozen=True)
class EffectChoice:
    """An effect of the model: its name and the keyword options of its factory (e.g. joints, joint)."""
    name: str
    options: tuple[tuple[str, object], ...] = ()

    def build(self, n_joints: int) -> Effect:
        if self.name not in MODEL_EFFECTS:
            raise ValueError(f"effect {self.name!r} cannot be part of the robot model "
                             f"(expected one of: {', '.join(MODEL_EFFECTS)})")
        return by_name(self.name, n_joints, **dict(self.options))

    @property
    def label(self) -> str:
        opts = dict(self.options)
        if "joint" in opts:
            return f"{self.name}(J{opts['joint']})"
        if "joints" in opts:
            return f"{self.name}(J{','.join(str(j) for j in opts['joints'])})"
        return self.name


@dataclass(frozen=True, eq=False)
class FittedEffect:
    """An identified effect: values and standard deviations (K,) in ``unit`` (NaN std = not identified,
    value kept at 0)."""
    choice: EffectChoice
    values: np.ndarray
    std: np.ndarray
    param_names: tuple[str, ...]
    unit: str

    def to_dict(self) -> dict:
        params = {}
        for name, v, s in zip(self.param_names, self.values, self.std):
            row = {"value": float(v), "std": None if not np.isfinite(s) else float(s), "unit": self.unit}
            if self.unit == "rad/(N*m)" and v != 0:
                row["stiffness_Nm_per_rad"] = float(1.0 / v)
            params[name] = row
        return {"name": self.choice.name, "options": {k: (list(v) if isinstance(v, tuple) else v)
                                                      for k, v in self.choice.options},
                "params": params}

    @classmethod
    def from_dict(cls, d: dict, n_joints: int) -> "FittedEffect":
        opts = tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in (d.get("options") or {}).items())
        choice = EffectChoice(d["name"], opts)
        eff = choice.build(n_joints)
        vals = np.array([float(d["params"][n]["value"]) for n in eff.param_names])
        std = np.array([np.nan if d["params"][n].get("std") is None else float(d["params"][n]["std"])
                        for n in eff.param_names])
        return cls(choice, vals, std, eff.param_names, eff.unit)


def effect_state(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> tuple[np.ndarray, np.ndarray]:
    """Joint deviation dq (N, n) rad and link-length scale (N,) of ``effects`` [(Effect, values (K,)), ...]."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    dq, scale = np.zeros_like(q), np.ones(len(q))
    for eff, values in effects:
        b = eff.basis(kin, q, meta)
        if b.dq is not None:
            dq += b.dq @ np.asarray(values, float)
        if b.scale is not None:
            scale += b.scale @ np.asarray(values, float)
        if b.dp is not None:
            raise ValueError(f"effect {eff.name!r} acts on the measurement, not on the robot")
    return dq, scale


def elastic_flange(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """T_base_flange (N, 4, 4) of the robot with geometry ``kin`` and ``effects`` (exact, not linearised)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    if not effects:
        return chain(kin, q, full=False).T_base_flange
    dq, scale = effect_state(kin, q, meta, effects)
    if np.all(scale == 1.0):
        return chain(kin, q + dq, full=False).T_base_flange
    return chain(kin, q + dq, a=kin.a_mm * scale[:, None], d=kin.d_mm * scale[:, None], full=False).T_base_flange


def elastic_smr_tracker(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """SMR positions (N, 3) mm in the tracker frame of the elasto-geometric model."""
    T = elastic_flange(kin, q_rad, meta, effects)
    return transform_points(kin.T_tracker_base, transform_points(T, kin.p_flange_smr_mm))


def _jacobian(kin, q, meta, built, values):
    """(p_tracker (N, 3), J_geo (N, 3, P), R_eff (N, 3, K)) at the current model."""
    pairs = list(zip(built, values))
    dq, scale = effect_state(kin, q, meta, pairs) if built else (np.zeros_like(q), np.ones(len(q)))
    _, J = identification_jacobian(kin, q + dq)
    p = elastic_smr_tracker(kin, q, meta, pairs)
    R = [effect_regressor(kin, q, meta, e, jacobian=(None, J)) for e in built]
    R = np.concatenate(R, axis=2) if R else np.zeros((len(q), 3, 0))
    return p, J, R


@dataclass(frozen=True, eq=False)
class ElasticResult:
    """Jointly identified geometry and effects, with diagnostics. ``residual_tracker_mm`` (N, 3) = measured -
    model at the fitted points; ``unidentifiable`` lists effect parameters the pose set cannot separate."""
    kinematics: Kinematics
    effects: tuple[FittedEffect, ...]
    unidentifiable: tuple[Unidentifiable, ...]
    residual_tracker_mm: np.ndarray
    sigma0: float
    iterations: int
    converged: bool
    condition_number: float

    def pairs(self, n_joints: int) -> list:
        return [(fe.choice.build(n_joints), fe.values) for fe in self.effects]


def calibrate_elastic(kin_geo: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
                      cov_mm2: np.ndarray | None, meta: Mapping, choices, options: CalibrationOptions = CalibrationOptions(),
                      max_iter: int = 50) -> ElasticResult:
    """Levenberg-Marquardt over the geometric parameters ``geo_cols`` (ParamLayout indices identified by the
    geometric calibration) and the parameters of ``choices`` (EffectChoice), starting from the geometric
    solution ``kin_geo`` with zero effects. Effect parameters linearly dependent on the geometry (or on one
    another) are fixed at zero and reported."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    p_meas = np.asarray(p_tracker_mm, float)
    layout = ParamLayout.of(kin_geo)
    built = [c.build(kin_geo.n) for c in choices]
    K = sum(e.k for e in built)
    eff_names = tuple(f"{c.label}.{n}" for c, e in zip(choices, built) for n in e.param_names)
    W = whitening(cov_mm2, len(q))
    kin = kin_geo
    x = np.zeros(K)
    split = np.cumsum([e.k for e in built])[:-1]
    _, J, R = _jacobian(kin, q, meta, built, np.split(x, split))
    A_full = _whiten(W, np.concatenate([J[:, :, geo_cols], R], axis=2)).reshape(-1, len(geo_cols) + K)
    names = tuple(layout.names[c] for c in geo_cols) + eff_names
    ident = analyse_identifiability(A_full, names, list(range(len(names))), options.rank_tol)
    keep = ident.keep.copy()
    keep[: len(geo_cols)] = True                       # the geometry stays as identified
    eff_keep = keep[len(geo_cols):]
    D = np.linalg.norm(A_full[:, keep], axis=0)
    D[D == 0] = 1.0
    P = int(keep.sum())

    def residual_and_A(kin, x):
        p, J, R = _jacobian(kin, q, meta, built, np.split(x, split))
        r = _whiten(W, p_meas - p).reshape(-1)
        A = _whiten(W, np.concatenate([J[:, :, geo_cols], R[:, :, eff_keep]], axis=2)).reshape(-1, P) / D
        return r, A

    def step(state, dx_scaled):
        kin, x = state
        dx = dx_scaled / D
        full = np.zeros(layout.size)
        full[geo_cols] = dx[: len(geo_cols)]
        x_new = x.copy()
        x_new[eff_keep] += dx[len(geo_cols):]
        return (apply_update(kin, full), x_new), dx

    fit = levenberg_marquardt((kin, x), lambda s: residual_and_A(*s), step, options.ridge_mu, max_iter,
                              options.step_tol)
    (kin, x), r, A, cost, it, converged = fit.state, fit.r, fit.A, fit.cost, fit.iterations, fit.converged
    m = len(r)
    sigma0 = float(np.sqrt(cost / max(m - P, 1)))
    cov = sigma0**2 * np.linalg.pinv(A.T @ A)
    std_all = np.sqrt(np.maximum(np.diag(cov), 0.0)) / D
    std_eff = np.full(K, np.nan)
    std_eff[eff_keep] = std_all[len(geo_cols):]
    fitted, start = [], 0
    for c, e in zip(choices, built):
        sl = slice(start, start + e.k)
        fitted.append(FittedEffect(c, x[sl].copy(), std_eff[sl], e.param_names, e.unit))
        start += e.k
    unident = tuple(u for u in ident.unidentifiable if u.name in eff_names)
    p_model = elastic_smr_tracker(kin, q, meta, [(e, f.values) for e, f in zip(built, fitted)])
    return ElasticResult(kin, tuple(fitted), unident, p_meas - p_model, sigma0, it, converged,
                         ident.condition_number)


# ---------------------------------------------------------------- selection by cross-validation
@dataclass(frozen=True)
class EffectTrial:
    """One candidate tried in one round of the forward selection: its CV RMS (mm) against the model so far."""
    round: int
    label: str
    cv_rms_mm: float
    base_cv_rms_mm: float
    gain: float
    t: float
    taken: bool

    def to_dict(self) -> dict:
        return {"round": self.round, "effect": self.label, "cv_rms_mm": self.cv_rms_mm,
                "base_cv_rms_mm": self.base_cv_rms_mm, "gain": self.gain, "t": self.t, "taken": self.taken}


@dataclass(frozen=True, eq=False)
class EffectSelection:
    taken: tuple[EffectChoice, ...]
    trials: tuple[EffectTrial, ...]
    geometric_cv_rms_mm: float
    final_cv_rms_mm: float
    folds: int

    def to_dict(self) -> dict:
        return {"method": f"forward selection, {self.folds}-fold CV on the calibration points (linearised at the "
                          "geometric solution); an effect is taken when the paired t of the per-point squared "
                          "errors exceeds 3 and the CV RMS drops by more than 2 %",
                "taken": [c.label for c in self.taken], "geometric_cv_rms_mm": self.geometric_cv_rms_mm,
                "final_cv_rms_mm": self.final_cv_rms_mm, "trials": [t.to_dict() for t in self.trials]}


def candidate_effects(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, link_masses_kg=DEFAULT_LINK_MASSES_KG
                      ) -> list[EffectChoice]:
    """The effects ``auto`` tries on this data: gravity compliance of the joints whose gravity torque varies,
    gear cyclic error of every joint, backlash (with approach signs), thermal scale (with time or temperature),
    wrist coupling (6 joints)."""
    q = np.atleast_2d(q_rad)
    pay = meta.get("payload_kg")
    tau = gravity_torques(kin, q, np.resize(np.asarray(link_masses_kg, float), kin.n),
                          np.asarray(0.0 if pay is None else pay, float))
    spread = tau.std(axis=0)
    loaded = tuple(int(j) + 1 for j in np.flatnonzero(spread > 0.05 * spread.max())) if spread.max() > 0 else ()
    loaded = tuple(j for j in loaded if j in (2, 3)) or loaded[:2]
    out = [EffectChoice("joint_compliance", (("joints", loaded),))] if loaded else []
    out += [EffectChoice("gear_cyclic", (("joint", j),)) for j in range(1, kin.n + 1)]
    if meta.get("approach") is not None and np.any(np.asarray(meta["approach"]) != 0):
        out.append(EffectChoice("backlash", (("joints", tuple(range(1, min(kin.n, 6) + 1))),)))
    if meta.get("t_s") is not None or meta.get("temp_c") is not None:
        out.append(EffectChoice("thermal_drift"))
    if kin.n >= 6:
        out.append(EffectChoice("axis_coupling"))
    return out


def kfold(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """Fold number (N,) of each point: a seeded random permutation cut into ``folds`` parts."""
    return np.random.default_rng(seed).permutation(n) % folds


def _cv_squared_errors(blocks, r0, W, fold) -> np.ndarray:
    """Per-point held-out squared error (N,) mm^2 of the linear model r0 ~ [blocks] x, k-fold."""
    A = np.concatenate(blocks, axis=2)                          # (N, 3, P) mm per unit
    N, _, P = A.shape
    Aw = _whiten(W, A)
    rw = _whiten(W, r0)
    scale = np.linalg.norm(Aw.reshape(-1, P), axis=0)
    scale[scale == 0] = 1.0
    se = np.empty(N)
    for k in np.unique(fold):
        tr, te = fold != k, fold == k
        x = np.linalg.lstsq(Aw[tr].reshape(-1, P) / scale, rw[tr].reshape(-1), rcond=1e-10)[0] / scale
        e = r0[te] - A[te] @ x
        se[te] = np.sum(e**2, axis=1)
    return se


def select_effects(kin: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
                   cov_mm2: np.ndarray | None, meta: Mapping, candidates, folds: int = 5, seed: int = 0,
                   max_effects: int = 6) -> EffectSelection:
    """Forward selection of effects by k-fold CV around the geometric solution ``kin`` (identified columns
    ``geo_cols``): every round tries each remaining candidate on top of the geometry + the effects taken so
    far, and takes the best one whose CV gain is significant (``paired_gain``); stops when none is."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    p, J = identification_jacobian(kin, q)
    r0 = np.asarray(p_tracker_mm, float) - p
    W = whitening(cov_mm2, len(q))
    fold = kfold(len(q), folds, seed)
    regs = {c: effect_regressor(kin, q, meta, c.build(kin.n), jacobian=(p, J)) for c in candidates}
    taken: list[EffectChoice] = []
    base = _cv_squared_errors([J[:, :, geo_cols]], r0, W, fold)
    geo_rms = float(np.sqrt(np.mean(base)))
    trials: list[EffectTrial] = []
    for rnd in range(1, max_effects + 1):
        best = None
        for c in candidates:
            if c in taken:
                continue
            se = _cv_squared_errors([J[:, :, geo_cols]] + [regs[t] for t in taken] + [regs[c]], r0, W, fold)
            g = paired_gain(base, se)
            trials.append(EffectTrial(rnd, c.label, g.rms_cand_mm, g.rms_base_mm, g.gain, g.t, False))
            if g.significant and (best is None or g.rms_cand_mm < best[1].rms_cand_mm):
                best = (c, g, se, len(trials) - 1)
        if best is None:
            break
        c, g, se, i = best
        trials[i] = EffectTrial(**{**trials[i].__dict__, "taken": True})
        taken.append(c)
        base = se
    return EffectSelection(tuple(taken), tuple(trials), geo_rms, float(np.sqrt(np.mean(base))), folds)
