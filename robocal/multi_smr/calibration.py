"""Calibration with two or three SMRs on the tool: one robot, one flange offset per SMR.

Every pose gives S measured SMR centres (S = 2 or 3, tracker frame). The model is the geometric one of
``robocal.kinematics`` with a shared geometry and registration and one SMR offset ``p_flange_smr_mm[s]`` per SMR;
the identification Jacobian of SMR s is that of the single-SMR model with its offset, its tool columns moved into
SMR s's own block. Identifiability is analysed over the stacked Jacobian (base, the SMR offsets, then the joints
from the last to the first): parameters of the last joint that every offset absorbs are held at nominal, so the
offsets are expressed in the nominal last-joint frame.

With three SMRs the flange orientation is observable: ``orientation_errors_arcsec`` compares the model's flange
orientation with the one fitted (Kabsch) to the three measured centres at each pose.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.identify.lm import levenberg_marquardt
from robocal.kinematics.frames import fit_rigid, transform_points
from robocal.identify.identification import (CalibrationOptions, IdentificationError, Unidentifiable, analyse_identifiability, priority_order)
from robocal.identify.whitened import whiten, whitening
from robocal.kinematics.models import Kinematics, ParamLayout, apply_update, fk, identification_jacobian, smr_base
from .three_smr_pose import fit_points_pose


@dataclass(frozen=True, eq=False)
class MultiSMRResult:
    """Identified geometry (``kinematics``, its SMR offset = SMR 1's) and every SMR's offset (S, 3) mm in the
    flange frame; ``residual_tracker_mm`` (S, N, 3) measured - model; ``identified`` / ``unidentifiable`` over
    the stacked parameter list (SMR offsets named smr{s}_x/y/z)."""
    kinematics: Kinematics
    p_flange_smr_mm: np.ndarray
    identified: tuple[str, ...]
    unidentifiable: tuple[Unidentifiable, ...]
    residual_tracker_mm: np.ndarray
    sigma0: float
    iterations: int
    converged: bool
    condition_number: float

    def predict_tracker(self, q_rad: np.ndarray) -> np.ndarray:
        """Model positions (S, N, 3) mm of every SMR in the tracker frame."""
        return predict_multi(self.kinematics, self.p_flange_smr_mm, q_rad)


def predict_multi(kin: Kinematics, offsets_mm: np.ndarray, q_rad: np.ndarray) -> np.ndarray:
    """SMR positions (S, N, 3) mm in the tracker frame for flange offsets (S, 3)."""
    T = kin.T_tracker_base @ fk(kin, np.atleast_2d(q_rad))
    return np.stack([transform_points(T, o) for o in np.asarray(offsets_mm, float)])


def _names(layout: ParamLayout, S: int) -> tuple[str, ...]:
    nj = layout.n_joint
    return layout.names[: nj + 6] + tuple(f"smr{s + 1}_{a}" for s in range(S) for a in "xyz")


def _stacked(kin, offsets, q, W):
    """(p (S*N, 3), J (S*N, 3, P_ext)) of the stacked SMRs; W whitening of the stacked rows or None."""
    layout = ParamLayout.of(kin)
    nj = layout.n_joint
    S, N = len(offsets), len(q)
    J = np.zeros((S * N, 3, nj + 6 + 3 * S))
    p = np.empty((S * N, 3))
    for s, off in enumerate(offsets):
        ps, Js = identification_jacobian(kin.with_(p_flange_smr_mm=off), q)
        rows = slice(s * N, (s + 1) * N)
        p[rows] = ps
        J[rows, :, : nj + 6] = Js[:, :, : nj + 6]
        J[rows, :, nj + 6 + 3 * s: nj + 9 + 3 * s] = Js[:, :, nj + 6:]
    return p, J


def calibrate_multi_smr(kin0: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, offsets0_mm: np.ndarray,
                        cov_mm2: np.ndarray | None = None, options: CalibrationOptions = CalibrationOptions(method="lm"),
                        max_iter: int = 100) -> MultiSMRResult:
    """Identify one robot from S SMRs: q_rad (N, n), p_tracker_mm (S, N, 3) measured centres, offsets0_mm (S, 3)
    nominal offsets in the flange frame, cov_mm2 (S, N, 3, 3) optional. Levenberg-Marquardt on the stacked,
    column-scaled problem; registration first by a closed-form rigid fit of all SMRs."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    P = np.asarray(p_tracker_mm, float)
    offsets = np.array(offsets0_mm, float).reshape(-1, 3)
    S, N = len(offsets), len(q)
    if P.shape != (S, N, 3):
        raise IdentificationError(f"expected measured points of shape ({S}, {N}, 3), got {P.shape}")
    p_nom = np.concatenate([smr_base(kin0.with_(p_flange_smr_mm=o), q) for o in offsets])
    kin = kin0.with_(T_tracker_base=fit_rigid(p_nom, P.reshape(-1, 3)), p_flange_smr_mm=offsets[0])
    p_meas = P.reshape(-1, 3)
    W = whitening(None if cov_mm2 is None else np.asarray(cov_mm2, float).reshape(-1, 3, 3), S * N)
    layout = ParamLayout.of(kin)
    nj = layout.n_joint
    names = _names(layout, S)
    base_order = priority_order(layout)                       # base, tool, joints last -> first
    order = list(range(nj, nj + 6)) + list(range(nj + 6, nj + 6 + 3 * S)) + [c for c in base_order if c < nj]
    _, J = _stacked(kin, offsets, q, W)
    A = whiten(W, J).reshape(-1, len(names))
    ident = analyse_identifiability(A, names, order, options.rank_tol, options.fixed)
    cols = np.flatnonzero(ident.keep)
    if 3 * S * N <= len(cols):
        raise IdentificationError(f"{N} poses x {S} SMRs cannot determine {len(cols)} parameters")
    D = np.linalg.norm(A[:, cols], axis=0)

    def lin(kin, offsets):
        p, J = _stacked(kin, offsets, q, W)
        r = whiten(W, p_meas - p).reshape(-1)
        return r, whiten(W, J[:, :, cols]).reshape(-1, len(cols)) / D

    def step(state, dxs):
        kin, offsets = state
        full = np.zeros(len(names))
        full[cols] = dxs / D
        geo = np.zeros(layout.size)
        geo[: nj + 6] = full[: nj + 6]
        return (apply_update(kin, geo), offsets + full[nj + 6:].reshape(S, 3)), full[cols]

    fit = levenberg_marquardt((kin, offsets), lambda s: lin(*s), step, options.ridge_mu, max_iter, options.step_tol)
    (kin, offsets), m, cost, it, converged = fit.state, fit.normal.m, fit.cost, fit.iterations, fit.converged
    kin = kin.with_(p_flange_smr_mm=offsets[0])
    res = P - predict_multi(kin, offsets, q)
    sigma0 = float(np.sqrt(cost / max(m - len(cols), 1)))
    return MultiSMRResult(kin, offsets, tuple(names[c] for c in cols), ident.unidentifiable, res, sigma0, it,
                          converged, ident.condition_number)


def orientation_errors_arcsec(kin: Kinematics, offsets_mm: np.ndarray, q_rad: np.ndarray,
                              p_tracker_mm: np.ndarray) -> np.ndarray:
    """Angle (N,) in arc seconds between the model's flange orientation (tracker frame) and the orientation
    fitted to the three measured SMR centres (S=3, N, 3) with the model's offsets."""
    T_model = kin.T_tracker_base @ fk(kin, np.atleast_2d(q_rad))
    T_meas = fit_points_pose(np.asarray(offsets_mm, float), np.swapaxes(np.asarray(p_tracker_mm, float), 0, 1))
    R = T_meas[:, :3, :3] @ np.swapaxes(T_model[:, :3, :3], 1, 2)
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    angle = np.arctan2(np.linalg.norm(v, axis=1) / 2.0, (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0)
    return np.degrees(angle) * 3600.0
