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
from .bases import meta_rows
from .cv import CV_MAX_ROWS, capped_rows
from .fit import ElasticResult, calibrate_elastic
from .library import LibraryOptions, candidates, scan_families
from .model import EffectChoice, FittedEffect
from .physical import reading
from .select import EffectSelection, select_effects


@dataclass(frozen=True)
class EngineOptions:
    """Cross-validation folds and seed, at most ``max_effects`` effects, the library's options, and at most
    ``max_rows`` rows in the selection (a seeded subset of the rows beyond: the choice needs no more)."""
    folds: int = 5
    seed: int = 0
    max_effects: int = 6
    library: LibraryOptions = field(default_factory=LibraryOptions)
    max_rows: int = CV_MAX_ROWS


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
           options: EngineOptions = EngineOptions(), of_rows: int | None = None) -> EngineResult:
    """Candidates + selection on the calibration rows (no fit yet): what ``effects: auto`` takes. Beyond
    ``options.max_rows`` rows the selection cross-validates a seeded subset of that many (the candidates, what the
    data can reveal and the physical readings are those of all the rows given); ``of_rows``: the calibration rows
    these rows already are a subset of (the caller gathered only them), reported with the selection."""
    cands, cannot = candidates(kin_geo, q_rad, meta, gravity, options.library)
    scans, not_scanned = scan_families(q_rad, options.library)

    def plausible(choice: EffectChoice, values: np.ndarray) -> bool:
        eff = choice.build(kin_geo.n)
        fe = FittedEffect(choice, values, np.full(eff.k, np.nan), eff.param_names, eff.unit)
        return reading(fe, kin_geo, q_rad, meta, gravity, options.library)["plausible"]
    rows = capped_rows(len(q_rad), options.max_rows, options.seed)
    q, p, cov, m = q_rad, p_tracker_mm, cov_mm2, meta
    if rows is not None:
        q, p, m = np.asarray(q_rad)[rows], np.asarray(p_tracker_mm)[rows], meta_rows(meta, rows)
        cov = None if cov_mm2 is None else np.asarray(cov_mm2)[rows]
    sel = select_effects(kin_geo, geo_cols, q, p, cov, m, cands, options.folds, options.seed, options.max_effects,
                         plausible, scans, of_rows=of_rows or len(q_rad))
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
