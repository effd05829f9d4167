"""The elasto-geometric robot model: effects as parameters of the calibrated model itself.

``EffectChoice`` names one effect with the options of its factory (``robocal.effects.bases.by_name``), ``FittedEffect``
is an identified effect with units, and ``elastic_flange`` / ``elastic_smr_tracker`` evaluate the chain exactly
at ``q + dq`` with scaled links (``effect_state``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .bases import MODEL_EFFECTS, Effect, by_name, effect_state
from robocal.kinematics.frames import transform_points
from robocal.kinematics.models import Kinematics, chain


@dataclass(frozen=True)
class EffectChoice:
    """An effect of the model: its name and the keyword options of its factory (e.g. joints, joint)."""
    name: str
    options: tuple[tuple[str, object], ...] = ()

    def build(self, n_joints: int) -> Effect:
        """The effect (ValueError names an unknown effect or option)."""
        if self.name not in MODEL_EFFECTS:
            raise ValueError(f"effect {self.name!r} cannot be part of the robot model "
                             f"(expected one of: {', '.join(MODEL_EFFECTS)})")
        return by_name(self.name, n_joints, **dict(self.options))

    @property
    def label(self) -> str:
        """``name(J2,3)``, with the options that differ from the candidates' defaults (``gear_cyclic(J2 h1,3)``,
        ``joint_compliance(J2,3 levers)``, ``registration_drift(order, degree 2)``, ``thermal_drift(tau 1 h)``)."""
        opts = dict(self.options)
        parts = []
        if "joint" in opts:
            parts.append(f"J{opts['joint']}")
        if "joints" in opts:
            parts.append(f"J{','.join(str(j) for j in opts['joints'])}")
        if opts.get("memory_joints"):
            parts.append(f"memory J{','.join(str(j) for j in opts['memory_joints'])}")
        if "harmonics" in opts and tuple(opts["harmonics"]) != (1, 2):
            parts.append(f"h{','.join(str(h) for h in opts['harmonics'])}")
        if opts.get("form") not in (None, "gravity"):
            parts.append(str(opts["form"]))
        if "clock" in opts:
            parts.append("time" if opts["clock"] == "t_s" else "measurement order")
        if opts.get("degree", 1) != 1:
            parts.append(f"degree {opts['degree']}")
        if "tau_s" in opts:
            parts.append(f"tau {opts['tau_s'] / 3600.0:g} h")
        return self.name + (f"({' '.join(parts)})" if parts else "")

    @classmethod
    def of_dict(cls, d: dict) -> "EffectChoice":
        """The choice of a fitted effect's dict (``FittedEffect.to_dict``: its name and options, lists as tuples), or
        of a config's ``calibration.effects`` item as ``{"name", "options": its params}``."""
        opts = (d.get("options") or {}).items()
        return cls(d["name"], tuple((k, tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in opts))

    def to_spec(self) -> dict:
        """The effect as a ``calibration.effects`` item of a cell's config: ``{"name", "params"}`` with plain
        values (tuples as lists), so that the config reads back this choice."""
        def plain(v):
            return [plain(x) for x in v] if isinstance(v, (tuple, list, np.ndarray)) else (
                v.item() if isinstance(v, np.generic) else v)
        return {"name": self.name, "params": {k: plain(v) for k, v in self.options}}

    def with_options(self, **changes) -> "EffectChoice":
        """The same effect with some options replaced (keys in the order of the original)."""
        opts = dict(self.options)
        opts.update(changes)
        return EffectChoice(self.name, tuple(opts.items()))


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
        choice = EffectChoice.of_dict(d)
        eff = choice.build(n_joints)
        vals = np.array([float(d["params"][n]["value"]) for n in eff.param_names])
        std = np.array([np.nan if d["params"][n].get("std") is None else float(d["params"][n]["std"])
                        for n in eff.param_names])
        return cls(choice, vals, std, eff.param_names, eff.unit)


def _flange(kin, q, dq, scale) -> np.ndarray:
    if np.all(scale == 1.0):
        return chain(kin, q + dq, full=False, axes=False).T_base_flange
    return chain(kin, q + dq, a=kin.a_mm * scale[:, None], d=kin.d_mm * scale[:, None], full=False,
                 axes=False).T_base_flange


def elastic_flange(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """T_base_flange (N, 4, 4) of the robot with geometry ``kin`` and ``effects`` (exact, not linearised; a drift
    of the measurement does not move the robot)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    if not effects:
        return chain(kin, q, full=False, axes=False).T_base_flange
    dq, scale, _ = effect_state(kin, q, meta, effects)
    return _flange(kin, q, dq, scale)


def elastic_smr_tracker(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """SMR positions (N, 3) mm in the tracker frame of the elasto-geometric model (drift of the measurement
    included)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    dq, scale, dp = effect_state(kin, q, meta, effects)
    T = _flange(kin, q, dq, scale)
    return transform_points(kin.T_tracker_base, transform_points(T, kin.p_flange_smr_mm)) + dp
