"""Joint identification of the geometry and the chosen effects (Levenberg-Marquardt, identifiability analysis
over both): ``calibrate_elastic``. Units: compliance c_j in rad/(N*m) (stiffness 1/c_j in N*m/rad reported),
harmonics and backlash in rad, lag in rad per rad of move, thermal growth per unit warm-up state, coupling 1,
drift mm or rad per clock span."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .bases import combine, effect_regressor, meta_rows
from robocal.identify.identification import CalibrationOptions, Unidentifiable, analyse_identifiability
from robocal.identify.whitened import DESIGN_ROWS, DesignFactor, whiten, whitening
from robocal.kinematics.models import Kinematics, ParamLayout, apply_update, identification_jacobian
from robocal.identify.lm import Normal, levenberg_marquardt
from robocal.identify.parameters import GEOMETRY_AND_EFFECTS, ParameterTable
from .model import FittedEffect, elastic_smr_tracker


def _jacobian(kin, q, meta, built, values):
    """(p_tracker (N, 3), J_geo (N, 3, P), R_eff (N, 3, K)) at the current model (each basis evaluated once)."""
    bases = [e.basis(kin, q, meta) for e in built]
    dq, scale, dp = combine(q, bases, values)
    if np.all(scale == 1.0):
        p, J = identification_jacobian(kin, q + dq)
    else:
        _, J = identification_jacobian(kin, q + dq)
        p = elastic_smr_tracker(kin, q, meta, list(zip(built, values))) - dp
    R = [effect_regressor(kin, q, meta, e, jacobian=(None, J), basis=b) for e, b in zip(built, bases)]
    R = np.concatenate(R, axis=2) if R else np.zeros((len(q), 3, 0))
    return p + dp, J, R


def _whitened_design(W, J: np.ndarray, geo_cols: np.ndarray, R: np.ndarray, eff_cols: np.ndarray,
                     D: np.ndarray) -> np.ndarray:
    """Whitened design (3N, P) = W [J[:, :, geo_cols] R[:, :, eff_cols]] / D of one block of rows, gathered and
    whitened into one array (no gathered or concatenated copies)."""
    G = len(geo_cols)
    A = np.empty((len(J), 3, G + np.arange(R.shape[2])[eff_cols].size))
    if W is None:
        A[:, :, :G], A[:, :, G:] = J[:, :, geo_cols], R[:, :, eff_cols]
    else:
        np.matmul(W, J[:, :, geo_cols], out=A[:, :, :G])
        np.matmul(W, R[:, :, eff_cols], out=A[:, :, G:])
    A /= D
    return A.reshape(len(A) * 3, -1)


def _design_blocks(kin, x, split, q, p_meas, W, meta, built, geo_cols, eff_cols, D):
    """(r (3b,), A (3b, P)) whitened residual and design of consecutive row blocks of ``DESIGN_ROWS`` points at the
    model (kin, effect values x): the normal equations are sums over blocks, the design is never held for all rows."""
    values = np.split(x, split)
    for s in range(0, len(q), DESIGN_ROWS):
        b = slice(s, s + DESIGN_ROWS)
        p, J, R = _jacobian(kin, q[b], meta_rows(meta, b), built, values)
        Wb = None if W is None else W[b]
        yield whiten(Wb, p_meas[b] - p).reshape(-1), _whitened_design(Wb, J, geo_cols, R, eff_cols, D)


def _normal(blocks) -> Normal:
    out = None
    for r, A in blocks:
        ne = Normal.of(r, A)
        out = ne if out is None else out + ne
    return out


@dataclass(frozen=True, eq=False)
class ElasticResult:
    """Jointly identified geometry and effects, with diagnostics. ``residual_tracker_mm`` (N, 3) = measured -
    model at the fitted points; ``unidentifiable`` lists effect parameters the pose set cannot separate;
    ``geometry_std`` (P,) the std of the geometric parameters from this joint fit, over the full ``ParamLayout``
    (mm or rad, NaN where not identified)."""
    kinematics: Kinematics
    effects: tuple[FittedEffect, ...]
    unidentifiable: tuple[Unidentifiable, ...]
    residual_tracker_mm: np.ndarray
    sigma0: float
    iterations: int
    converged: bool
    condition_number: float
    geometry_std: np.ndarray | None = None

    def table(self, start: Kinematics, identified) -> ParameterTable:
        """The parameter record of the model (``robocal.identify.parameters``): deltas from ``start`` (the geometric fit's
        start), the geometric parameters ``identified`` with their std from this joint fit."""
        return ParameterTable.of(self.kinematics, start, identified, self.geometry_std, GEOMETRY_AND_EFFECTS,
                                 self.sigma0)

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
    design = dict(split=split, q=q, p_meas=p_meas, W=W, meta=meta, built=built, geo_cols=geo_cols)
    full = DesignFactor(A for _, A in _design_blocks(kin, x, **design, eff_cols=np.arange(K),
                                                     D=np.ones(len(geo_cols) + K)))
    names = tuple(layout.names[c] for c in geo_cols) + eff_names
    ident = analyse_identifiability(full.R, names, list(range(len(names))), options.rank_tol)
    keep = ident.keep.copy()
    keep[: len(geo_cols)] = True                       # the geometry stays as identified
    eff_keep = keep[len(geo_cols):]
    D = full.norms(keep)
    D[D == 0] = 1.0
    P = int(keep.sum())
    del full

    def step(state, dx_scaled):
        kin, x = state
        dx = dx_scaled / D
        full = np.zeros(layout.size)
        full[geo_cols] = dx[: len(geo_cols)]
        x_new = x.copy()
        x_new[eff_keep] += dx[len(geo_cols):]
        return (apply_update(kin, full), x_new), dx

    fit = levenberg_marquardt((kin, x), lambda s: _normal(_design_blocks(*s, **design, eff_cols=eff_keep, D=D)),
                              step, options.ridge_mu, max_iter, options.step_tol)
    (kin, x), cost, it, converged = fit.state, fit.cost, fit.iterations, fit.converged
    sigma0 = float(np.sqrt(cost / max(fit.normal.m - P, 1)))
    cov = sigma0**2 * np.linalg.pinv(fit.normal.H)
    std_all = np.sqrt(np.maximum(np.diag(cov), 0.0)) / D
    std_eff = np.full(K, np.nan)
    std_eff[eff_keep] = std_all[len(geo_cols):]
    std_geo = np.full(layout.size, np.nan)
    std_geo[geo_cols] = std_all[:len(geo_cols)]
    fitted, start = [], 0
    for c, e in zip(choices, built):
        sl = slice(start, start + e.k)
        fitted.append(FittedEffect(c, x[sl].copy(), std_eff[sl], e.param_names, e.unit))
        start += e.k
    unident = tuple(u for u in ident.unidentifiable if u.name in eff_names)
    p_model = elastic_smr_tracker(kin, q, meta, [(e, f.values) for e, f in zip(built, fitted)])
    return ElasticResult(kin, tuple(fitted), unident, p_meas - p_model, sigma0, it, converged,
                         ident.condition_number, std_geo)


