"""The one effect engine: which unmodelled effects the data support, fitted with the geometry.

``run_engine`` = candidates of the library (``library.candidates``) -> forward selection by blocked
cross-validation (``select.select_effects``) -> joint identification of the geometry and the taken effects with
the exact model (``fit.calibrate_elastic``) -> evidence for each taken effect (physical reading against its
range, ``physical.reading``; dependence on the measurement order, ``evidence``). ``campaign reprocess``
(``calibration.effects: auto``) and ``campaign diagnose`` both call it on the same rows, so they take the same
effects with the same values.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from robocal.kinematics.gravity import GravityModel
from robocal.identify.identification import CalibrationOptions
from robocal.kinematics.models import Kinematics
from .fit import ElasticResult, calibrate_elastic
from .library import LibraryOptions, candidates, scan_families
from .model import EffectChoice, FittedEffect
from .physical import reading
from .select import EffectSelection, select_effects


@dataclass(frozen=True)
class EngineOptions:
    """Cross-validation folds and seed, at most ``max_effects`` effects, and the library's options."""
    folds: int = 5
    seed: int = 0
    max_effects: int = 6
    library: LibraryOptions = field(default_factory=LibraryOptions)


@dataclass(frozen=True, eq=False)
class EngineResult:
    """``selection`` (steps, trials), ``cannot_tell`` (effects these data cannot reveal, with the reason) and
    ``candidates`` tried; ``elastic`` the joint fit of geometry + taken effects (None when nothing was taken)."""
    selection: EffectSelection
    cannot_tell: tuple[dict, ...]
    candidates: tuple[EffectChoice, ...]
    elastic: ElasticResult | None = None

    @property
    def taken(self) -> tuple[EffectChoice, ...]:
        return self.selection.taken


def select_candidates(kin_geo: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
           cov_mm2: np.ndarray | None, meta: Mapping, gravity: GravityModel = GravityModel(),
           options: EngineOptions = EngineOptions()) -> EngineResult:
    """Candidates + selection on the calibration rows (no fit yet): what ``effects: auto`` takes."""
    cands, cannot = candidates(kin_geo, q_rad, meta, gravity, options.library)
    scans, not_scanned = scan_families(q_rad, options.library)

    def plausible(choice: EffectChoice, values: np.ndarray) -> bool:
        eff = choice.build(kin_geo.n)
        fe = FittedEffect(choice, values, np.full(eff.k, np.nan), eff.param_names, eff.unit)
        return reading(fe, kin_geo, q_rad, meta, gravity, options.library)["plausible"]
    sel = select_effects(kin_geo, geo_cols, q_rad, p_tracker_mm, cov_mm2, meta, cands, options.folds, options.seed,
                         options.max_effects, plausible, scans)
    return EngineResult(sel, tuple(cannot + not_scanned), tuple(cands))


def run_engine(kin_geo: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
               cov_mm2: np.ndarray | None, meta: Mapping, gravity: GravityModel = GravityModel(),
               options: EngineOptions = EngineOptions(),
               calibration: CalibrationOptions = CalibrationOptions()) -> EngineResult:
    """``select_candidates`` and the joint fit of the geometry and the taken effects on the same rows."""
    res = select_candidates(kin_geo, geo_cols, q_rad, p_tracker_mm, cov_mm2, meta, gravity, options)
    if not res.taken:
        return res
    fit = calibrate_elastic(kin_geo, geo_cols, q_rad, p_tracker_mm, cov_mm2, meta, res.taken, calibration)
    return EngineResult(res.selection, res.cannot_tell, res.candidates, fit)
