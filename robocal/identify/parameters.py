"""The identified kinematic parameters of a calibrated model, as one record: ``ParameterTable``.

One row per identification candidate (``ParamLayout`` order): the value in the chain (mm or rad; None for the base
entries, which are a rigid frame, ``T_tracker_base``), the delta from the start of the fit (the nominal geometry
with the registered base and SMR offset: joint entries are deltas from nominal, base entries are relative to the
registered frame), its standard deviation from the fit that produced the model (None where not identified). The
model file carries it (``CalibratedModel.parameters``), so every output of the parameters renders the same numbers.
In the JSON form (``to_dict``) angles are in degrees, as everywhere at the edges.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from robocal.kinematics.models import Kinematics, ParamLayout, parameter_difference

GEOMETRY = "geometry"
GEOMETRIC_PRIOR = {"mm": 1.0, "rad": 1.0e-3, "mm/mm": 1.0e-3}   # prior std by unit (1 mm, 1 mrad, a track 1 mm/m)
GEOMETRY_AND_EFFECTS = "geometry + physical effects"
"""The fits a table comes from: the geometric identification, or the joint fit of the geometry and the effects."""


def geometric_prior_sigma(units) -> np.ndarray:
    """Prior std per geometric parameter from its unit ("mm", "rad" or "mm/mm")."""
    return np.array([GEOMETRIC_PRIOR[u] for u in units], float)


@dataclass(frozen=True)
class Parameter:
    """One candidate: ``unit`` "mm" or "rad"; ``value`` in the chain (None: a base entry); ``delta`` from the fit's
    start; ``std`` (None: not identified, fixed at its start value)."""
    name: str
    unit: str
    value: float | None
    delta: float
    std: float | None
    identified: bool

    def to_dict(self) -> dict:
        """JSON row, angles in degrees (unit "deg")."""
        rad = self.unit == "rad"
        scale = lambda v: None if v is None else float(np.degrees(v) if rad else v)  # noqa: E731
        return {"name": self.name, "unit": "deg" if self.unit == "rad" else self.unit, "value": scale(self.value),
                "delta": scale(self.delta), "std": scale(self.std), "identified": self.identified}

    @classmethod
    def from_dict(cls, d: Mapping) -> "Parameter":
        deg = d["unit"] == "deg"
        scale = lambda v: None if v is None else float(np.radians(v) if deg else v)  # noqa: E731
        return cls(str(d["name"]), "rad" if deg else str(d["unit"]), scale(d.get("value")), scale(d["delta"]),
                   scale(d.get("std")), bool(d["identified"]))


@dataclass(frozen=True)
class ParameterTable:
    """The parameters of a model and the fit they come from (``GEOMETRY`` or ``GEOMETRY_AND_EFFECTS``), with that
    fit's unit-weight error ``sigma0`` (the stds are scaled by it)."""
    fit: str
    sigma0: float
    rows: tuple[Parameter, ...]

    @classmethod
    def of(cls, kin: Kinematics, start: Kinematics, identified, std, fit: str, sigma0: float) -> "ParameterTable":
        """The table of model ``kin`` fitted from ``start``: ``identified`` names, ``std`` (P,) over the full
        ``ParamLayout`` (NaN where not identified)."""
        layout = ParamLayout.of(kin)
        delta = parameter_difference(kin, start)
        ident = set(identified)
        rows = tuple(Parameter(n, layout.unit(n), _value(kin, layout, c), float(delta[c]),
                               float(std[c]) if np.isfinite(std[c]) else None, n in ident)
                     for c, n in enumerate(layout.names))
        return cls(fit, float(sigma0), rows)

    def row(self, name: str) -> Parameter | None:
        return next((r for r in self.rows if r.name == name), None)

    def to_dict(self) -> dict:
        return {"fit": self.fit, "sigma0": self.sigma0,
                "note": "delta from nominal (base: from the registered frame); std from the fit named; deg for angles",
                "rows": [r.to_dict() for r in self.rows]}

    @classmethod
    def from_dict(cls, d: Mapping) -> "ParameterTable":
        return cls(str(d["fit"]), float(d["sigma0"]), tuple(Parameter.from_dict(r) for r in d["rows"]))


def _value(kin: Kinematics, layout: ParamLayout, col: int) -> float | None:
    """The value of candidate ``col`` in the chain (mm or rad); None for a base entry."""
    joint = {c: (i, k) for c, i, k in layout.joint_cols}
    if col in joint:
        i, k = joint[col]
        return float((kin.theta_rad, kin.d_mm, kin.a_mm, kin.alpha_rad, kin.beta_rad)[k][i])
    name = layout.names[col]
    if name.startswith("tool_"):
        return float(kin.p_flange_smr_mm["xyz".index(name[-1])])
    return None
