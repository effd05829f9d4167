"""The calibrated model: the actual-pose predictor AP(theta) of seed 001.

``CalibratedModel`` = kinematic layer (identified geometry, registration, SMR) + optional residual layer
(IDW, GPR or any object with ``predict(q_rad, p_base_mm) -> (N, 3)`` and ``to_dict``), with the record of its
identified parameters (``robocal.identify.parameters.ParameterTable``: values, deltas, std of the fit that made it). It
predicts where the SMR really is for given joint angles, and is what target correction and evaluation use.
``to_dict`` / ``from_dict`` give a plain, unit-labelled structure for JSON or YAML (the file I/O lives in campaign/);
``from_dict`` reads the files of earlier versions, which have no parameter record.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from robocal.kinematics.frames import transform_points
from robocal.kinematics.models import Kinematics, fk
from robocal.effects.bases import effect_state
from robocal.effects.model import FittedEffect, elastic_flange
from .gp_layer import GPRResidual
from .joint_gp import JointGPResidual
from robocal.identify.parameters import ParameterTable
from .idw import IDWResidual
from .trend import TrendGPRResidual

FORMAT = "robocal-model/1"
RESIDUAL_KINDS = {"idw": IDWResidual, "gpr": GPRResidual, "joint_gp": JointGPResidual,
                  "trend_gpr": TrendGPRResidual}


@dataclass(frozen=True, eq=False)
class CalibratedModel:
    kinematics: Kinematics
    residual: Any = None
    meta: dict | None = None
    effects: tuple[FittedEffect, ...] = ()     # physical effects of the elasto-geometric model
    payload_kg: float | None = None            # payload assumed by the effects when a point gives none
    parameters: ParameterTable | None = None   # the identified kinematic parameters with their std (the record)

    def effect_meta(self, n: int, meta: Mapping | None = None) -> dict:
        """Per-point metadata of the effects: the given ``meta`` (payload_kg, approach, t_s, temp_c), the
        model's payload where none is given. Unknown approach or time count as zero (mean backlash, cold)."""
        out = dict(meta or {})
        if out.get("payload_kg") is None and self.payload_kg is not None:
            out["payload_kg"] = np.full(n, float(self.payload_kg))
        return out

    def flange_pose(self, q_rad: np.ndarray, meta: Mapping | None = None) -> np.ndarray:
        """T_base_flange (N, 4, 4) of the kinematic layer with its physical effects (the residual layer
        corrects position only)."""
        q = np.atleast_2d(q_rad)
        if not self.effects:
            return fk(self.kinematics, q)
        pairs = [(fe.choice.build(self.kinematics.n), fe.values) for fe in self.effects]
        return elastic_flange(self.kinematics, q, self.effect_meta(len(q), meta), pairs)

    def kinematic_smr_base(self, q_rad: np.ndarray, meta: Mapping | None = None) -> np.ndarray:
        """SMR position (N, 3) mm, base frame, kinematic layer (geometry + effects) only; a drift of the
        measurement (registration drift at the rows' clock) is where the tracker sees the SMR, in base axes."""
        q = np.atleast_2d(q_rad)
        p = transform_points(self.flange_pose(q, meta), self.kinematics.p_flange_smr_mm)
        drift = [(fe.choice.build(self.kinematics.n), fe.values) for fe in self.effects
                 if fe.choice.name == "registration_drift"]
        if drift and meta is not None:
            dp = effect_state(self.kinematics, q, self.effect_meta(len(q), meta), drift)[2]
            p = p + dp @ self.kinematics.T_tracker_base[:3, :3]
        return p

    def residual_base(self, q_rad: np.ndarray, p_kin_base_mm: np.ndarray | None = None) -> np.ndarray:
        """Predicted residual error (N, 3) mm in the base frame (zeros without a residual layer)."""
        q = np.atleast_2d(q_rad)
        if self.residual is None:
            return np.zeros((len(q), 3))
        p = self.kinematic_smr_base(q) if p_kin_base_mm is None else p_kin_base_mm
        return self.residual.predict(q, p)

    def smr_base(self, q_rad: np.ndarray, meta: Mapping | None = None) -> np.ndarray:
        """AP(theta): predicted actual SMR position (N, 3) mm in the base frame."""
        p = self.kinematic_smr_base(q_rad, meta)
        return p + self.residual_base(q_rad, p)

    def smr_tracker(self, q_rad: np.ndarray, meta: Mapping | None = None) -> np.ndarray:
        """Predicted actual SMR position (N, 3) mm in the tracker frame."""
        return transform_points(self.kinematics.T_tracker_base, self.smr_base(q_rad, meta))

    def to_dict(self) -> dict:
        return {"format": FORMAT,
                "units": {"length": "mm", "angle": "deg (in keys *_deg)", "frames": "T_tracker_base: base in tracker",
                          "effects": "per parameter (compliance rad/(N*m) with stiffness N*m/rad)"},
                "kinematics": self.kinematics.to_dict(),
                "effects": [fe.to_dict() for fe in self.effects], "payload_kg": self.payload_kg,
                "residual": None if self.residual is None else self.residual.to_dict(),
                "meta": self.meta or {},
                "parameters": None if self.parameters is None else self.parameters.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "CalibratedModel":
        if d.get("format") != FORMAT:
            raise ValueError(f"not a calibrated model file (format {d.get('format')!r}, expected {FORMAT!r})")
        res = d.get("residual")
        layer = None
        if res is not None:
            if res.get("kind") not in RESIDUAL_KINDS:
                raise ValueError(f"unknown residual layer kind {res.get('kind')!r}")
            layer = RESIDUAL_KINDS[res["kind"]].from_dict(res)
        kin = Kinematics.from_dict(d["kinematics"])
        effects = tuple(FittedEffect.from_dict(e, kin.n) for e in d.get("effects") or [])
        pay = d.get("payload_kg")
        table = d.get("parameters")                  # absent from the files of earlier versions
        return cls(kin, layer, d.get("meta") or {}, effects, None if pay is None else float(pay),
                   None if table is None else ParameterTable.from_dict(table))


def fit_idw_layer(kin: Kinematics, q_rad: np.ndarray, p_tracker_mm: np.ndarray, power: float = 2.0,
                  k_nearest: int = 8, weights: np.ndarray | None = None) -> IDWResidual:
    """IDW layer from calibration points: nodes at the model's SMR positions (base frame), values the
    residuals measured - model rotated into the base frame. Points with zero robust weight are left out."""
    keep = np.ones(len(q_rad), bool) if weights is None else np.asarray(weights) > 0
    p_kin = transform_points(fk(kin, q_rad[keep]), kin.p_flange_smr_mm)
    R = kin.T_tracker_base[:3, :3]
    p_meas_base = (p_tracker_mm[keep] - kin.T_tracker_base[:3, 3]) @ R
    return IDWResidual.fit(p_meas_base, p_meas_base - p_kin, power, k_nearest)
