"""The GPR residual layer of ``CalibratedModel`` (kind ``"gpr"``): one GP per base-frame axis on the kinematic
model's residuals, exact (``robocal.layers.gp``) or with inducing points (``robocal.layers.sparse_gp``)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.kinematics.frames import transform_points
from .gp import MultiOutputGP
from robocal.kinematics.models import Kinematics, fk


def gp_inputs(q_rad: np.ndarray, payload_kg=None) -> np.ndarray:
    """GP input matrix: joint angles (N, n) rad, plus the payload (kg, scalar or (N,)) as a last column."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    if payload_kg is None:
        return q
    return np.column_stack([q, np.broadcast_to(np.asarray(payload_kg, float), (len(q),))])


# ---------------------------------------------------------------- residual layer
@dataclass(frozen=True, eq=False)
class GPRResidual:
    """GPR residual layer: one GP per base-frame axis on the residual ``p_measured - p_model`` (mm) as a
    function of the joint angles (+ payload when ``uses_payload``). ``payload_kg`` is the payload assumed when
    ``predict`` is given none (the tool the robot carries now; see ``with_payload``)."""
    gp: "MultiOutputGP | SparseGP"          # exact, or inducing points beyond a size (robocal.layers.sparse_gp)
    uses_payload: bool = False
    payload_kg: float | None = None

    kind = "gpr"

    def _x(self, q_rad, payload_kg):
        if not self.uses_payload:
            return gp_inputs(q_rad)
        pay = self.payload_kg if payload_kg is None else payload_kg
        if pay is None:
            raise ValueError("this GPR layer takes the payload as an input: give payload_kg (or use with_payload)")
        return gp_inputs(q_rad, pay)

    def predict(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None) -> np.ndarray:
        """Predicted residual (N, 3) mm in the base frame at joint angles q_rad (N, n); p_base_mm is unused
        (a joint-keyed layer; the argument keeps the residual-layer interface)."""
        return self.gp.predict(self._x(q_rad, payload_kg))

    def predict_std(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None,
                    include_noise: bool = True) -> np.ndarray:
        """Predictive standard deviation (N, 3) mm per base-frame axis (eq. 8)."""
        return self.gp.predict_std(self._x(q_rad, payload_kg), include_noise)[1]

    def with_payload(self, payload_kg: float | None) -> "GPRResidual":
        return GPRResidual(self.gp, self.uses_payload, payload_kg)

    def to_dict(self) -> dict:
        return {"kind": "gpr", "frame": "base", "units": {"inputs": "rad (joints), kg (payload)", "outputs": "mm"},
                "uses_payload": self.uses_payload, "payload_kg": self.payload_kg, "gp": self.gp.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "GPRResidual":
        from .sparse_gp import SparseGP           # lazy: sparse_gp builds on this module
        pay = d.get("payload_kg")
        kind = d["gp"].get("approximation", "exact")
        if kind not in ("exact", SparseGP.kind):
            raise ValueError(f"unknown GP approximation {kind!r}")
        gp = SparseGP.from_dict(d["gp"]) if kind == SparseGP.kind else MultiOutputGP.from_dict(d["gp"])
        return cls(gp, bool(d.get("uses_payload", False)), None if pay is None else float(pay))


def fit_gpr_layer(kin: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, weights: np.ndarray | None = None,
                  payload_kg=None, n_restarts: int = 3, seed: int = 0, fast: bool = False) -> GPRResidual:
    """GPR layer from calibration points (mirror of ``fit_idw_layer``): residuals measured - model rotated
    into the base frame. Points with zero robust weight are left out. ``payload_kg`` (N,) makes the payload
    an input (pass it only when it varies across the points)."""
    keep = np.ones(len(q_rad), bool) if weights is None else np.asarray(weights) > 0
    q = np.asarray(q_rad, float)[keep]
    p_kin = transform_points(fk(kin, q), kin.p_flange_smr_mm)
    R = kin.T_tracker_base[:3, :3]
    p_meas_base = (np.asarray(p_tracker_mm, float)[keep] - kin.T_tracker_base[:3, 3]) @ R
    pay = None if payload_kg is None else np.broadcast_to(np.asarray(payload_kg, float), (len(q_rad),))[keep]
    if fast:
        gp = MultiOutputGP.fit_subset(gp_inputs(q, pay), p_meas_base - p_kin, seed=seed)
    else:
        gp = MultiOutputGP.fit(gp_inputs(q, pay), p_meas_base - p_kin, n_restarts=n_restarts, seed=seed)
    return GPRResidual(gp, pay is not None, None)
