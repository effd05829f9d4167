"""Inputs, options and results of the diagnosis: ``DiagnosisOptions``, ``DiagnosisInput`` and the result records
``Finding``, ``Region``, ``Diagnosis`` (``to_dict``: the JSON contract)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.measure.approach import approach_signs, moves_from_order
from robocal.kinematics.gravity import GravityModel
from robocal.effects.engine import EngineOptions
from robocal.kinematics.models import Kinematics
from .budget import ErrorBudget
from .jsonable import json_float, plain
from .next_steps import NextStep
from .remainder import Remainder


@dataclass(frozen=True)
class DiagnosisOptions:
    """What the diagnosis adds to the engine's answer: ``engine`` (the effect engine's options: folds, seed),
    confound and consistency thresholds, where-analysis and leftover settings."""
    engine: EngineOptions = field(default_factory=EngineOptions)
    confound_r: float = 0.7           # an effect whose displacement follows the measurement order this closely ...
    #                                   ... is one class with a drift in measurement order
    split_min_ratio: float = 0.25     # near/far or first/second half fits differing by more than this share: noted
    absorbed_limit: float = 0.95      # a candidate absorbed beyond this by the geometry is listed as cannot tell
    outlier_sigma: float = 5.0        # arrays without a baseline: gross outliers (robust sigma) set aside
    region_alpha: float = 0.01        # family-wise, Bonferroni over the regions of a stage
    region_min_ratio: float = 1.2     # a flagged region is at least this much above the floor
    region_min_points: int = 5        # regions (and each approach side) with fewer points are not tested
    max_regions: int = 12
    structure_z: float = 4.0          # neighbour test: structure along an input at this z
    neighbours: int = 10
    structure_max_points: int = 4000  # the neighbour test runs on at most this many rows (seeded subset)
    permutations: int = 200
    unexplained_ratio: float = 1.12   # held-out RMS above this x the (parameter-inflated) floor: unexplained ...
    floor_f_alpha: float = 1e-3       # ... and, with a floor from repeats, significantly so (F test at this level)
    cv_param_inflation: float = 1.25  # floor inflation per parameter share (held-out prediction with p parameters)
    layer_max_points: int = 2000      # the GPR layer that measures the structure left over: at most this many rows
    nonphysical_gear_arcsec: float = 300.0   # a gear harmonic beyond this is beyond any gearbox: not physical ...
    nonphysical_split: float = 1.0    # ... and so are parameters that differ between near/far reach or the halves
    nonphysical_split_z: float = 3.0  #     of the run by more than the effect itself, and by this x their noise
    term_t: float = 3.0               # a named term outside the model predicting held-out points at this paired t
    #                                   (and > 2 %: the claim standard of robocal.measure.stats): unexplained structure
    budget_boot: int = 400            # bootstrap resamples of the error budget's intervals
    seed: int = 0


@dataclass(frozen=True, eq=False)
class DiagnosisInput:
    """One dataset. Rows: calibration and test rows (repeats used for the floor are not passed), ``order`` (N,)
    their position in the measurement sequence (None: unknown, then backlash, read-back lag and drift in
    measurement order cannot be told). ``q_rad`` (N, n), ``p_mm`` (N, 3) tracker frame, ``cov_mm2`` (N, 3, 3)
    measurement covariance, ``calib``/``test`` (N,) bool. Metadata (each optional): ``t_s``, ``temp_c``,
    ``payload_kg`` (N,); ``approach`` (N, n) signs and ``move_rad``/``prev_move_rad`` (N, n) when computed over more
    rows than these (else from ``order``). ``noise_floor_dof``: points behind a floor measured from repeats.
    ``gravity``: the one gravity-torque model; ``baseline``/``baseline_identified``: the geometric fit to start
    from (reprocess's kinematic stage); ``nominal`` the model of the budget's nominal stage (base registered
    on the calibration rows); ``q_cmd_rad`` commanded joints when ``q_rad`` are read-back ones."""
    kin: Kinematics
    q_rad: np.ndarray
    p_mm: np.ndarray
    cov_mm2: np.ndarray
    calib: np.ndarray
    test: np.ndarray
    noise_floor_mm: float
    noise_floor_source: str = "specs"
    noise_floor_dof: int | None = None
    t_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    order: np.ndarray | None = None
    approach: np.ndarray | None = None
    move_rad: np.ndarray | None = None
    prev_move_rad: np.ndarray | None = None
    gravity: GravityModel = GravityModel()
    baseline: Kinematics | None = None
    baseline_identified: tuple[str, ...] | None = None
    nominal: Kinematics | None = None       # the nominal stage's model (registered here); None: ``kin``
    q_cmd_rad: np.ndarray | None = None      # commanded joints (N, n) beside read-back ``q_rad``, when both exist

    def meta(self) -> dict:
        """Per-row metadata of the effects (``robocal.effects``): approach and moves from the measurement order."""
        approach, move, prev = self.approach, self.move_rad, self.prev_move_rad
        if self.order is not None and (approach is None or move is None):
            rank = np.argsort(np.asarray(self.order, float), kind="stable")
            inv = np.empty_like(rank)
            inv[rank] = np.arange(len(rank))
            q = np.asarray(self.q_rad, float)[rank]
            if approach is None:
                approach = approach_signs(q)[inv]
            if move is None:
                m, p = moves_from_order(q)
                move, prev = m[inv], p[inv]
        return {"payload_kg": self.payload_kg, "approach": approach, "move": move, "prev_move": prev,
                "order": None if self.order is None else np.asarray(self.order, float), "t_s": self.t_s,
                "temp_c": self.temp_c}


@dataclass(frozen=True)
class Finding:
    effect: str
    joints: tuple[int, ...]
    accepted: bool
    test_rms_before_mm: float
    test_rms_after_mm: float
    evidence: dict

    def to_dict(self) -> dict:
        return {"effect": self.effect, "joints": [int(j) for j in self.joints], "accepted": bool(self.accepted),
                "test_rms_before_mm": json_float(self.test_rms_before_mm), "test_rms_after_mm": json_float(self.test_rms_after_mm),
                "evidence": plain(self.evidence)}


@dataclass(frozen=True)
class Region:
    """A region of the evaluated points; ``description`` names it in words with its RMS and the floor."""
    description: str
    rms_mm: float
    floor_mm: float
    n: int
    kind: str
    stage: str
    p_value: float
    extra: dict = field(default_factory=dict)

    @property
    def region(self) -> str:
        return self.extra.get("region", self.description)

    def to_dict(self) -> dict:
        d = {"description": self.description, "rms_mm": json_float(self.rms_mm), "floor_mm": json_float(self.floor_mm),
             "ratio": json_float(self.rms_mm / self.floor_mm) if self.floor_mm > 0 else None, "n": int(self.n),
             "kind": self.kind, "stage": self.stage, "p_value": json_float(self.p_value)}
        d.update(plain(self.extra))
        return d


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of ``diagnose``. ``to_dict`` gives the JSON contract of issue 7 (plus detail keys).
    ``unexplained_structure``: the one definition of what is left (excess of the held-out RMS over the floor after
    the final model, and how much a non-parametric layer removes of it on held-out points)."""
    noise_floor_mm: float
    noise_floor_source: str
    baseline_test_rms_mm: float
    final_test_rms_mm: float
    unexplained: bool
    findings: tuple[Finding, ...]
    where: tuple[Region, ...]
    undiagnosable: tuple[dict, ...]
    evaluation: str                 # "test" | "cv" (no test rows: cross-validated calibration residuals)
    unexplained_structure: dict
    structure: dict
    maps: dict
    notes: tuple[str, ...]
    n_calib: int
    n_test: int
    outliers: tuple[int, ...]       # row indices set aside as gross outliers (or by the fault screen)
    kinematics: Kinematics
    effects: tuple                  # FittedEffect of the final model
    stages: tuple[dict, ...]        # test/CV RMS after each accepted step (step 0 = geometric)
    selection: dict                 # the engine's selection (robocal.effects.select.EffectSelection.to_dict)
    budget: ErrorBudget | None = None
    remainder: Remainder | None = None
    layer: dict = field(default_factory=dict)          # what the residual layer removes (``layer_terms``)
    next_steps: tuple[NextStep, ...] = ()               # per undecided class: experiment, predicted shrinkage

    @property
    def accepted_effects(self) -> tuple[str, ...]:
        return tuple(f.effect for f in self.findings if f.accepted)

    def to_dict(self) -> dict:
        return {
            "noise_floor_mm": json_float(self.noise_floor_mm), "noise_floor_source": self.noise_floor_source,
            "baseline_test_rms_mm": json_float(self.baseline_test_rms_mm), "final_test_rms_mm": json_float(self.final_test_rms_mm),
            "unexplained": bool(self.unexplained),
            "findings": [f.to_dict() for f in self.findings],
            "where": [r.to_dict() for r in self.where],
            "unexplained_structure": plain(self.unexplained_structure),
            "evaluation": self.evaluation, "n_calib": self.n_calib, "n_test": self.n_test,
            "outliers": len(self.outliers), "undiagnosable": plain(list(self.undiagnosable)),
            "structure": plain(self.structure), "stages": plain(list(self.stages)), "notes": list(self.notes),
            "effects": [fe.to_dict() for fe in self.effects], "selection": plain(self.selection),
            "maps": plain(self.maps),
            "budget": None if self.budget is None else self.budget.to_dict(),
            "remainder": None if self.remainder is None else self.remainder.to_dict(),
            "layer": plain(self.layer), "next_steps": [s.to_dict() for s in self.next_steps],
        }
