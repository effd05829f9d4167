"""Inputs, options and results of the diagnosis: ``DiagnosisOptions`` (every threshold), ``DiagnosisInput``,
``NestReadings`` and the result records ``Finding``, ``Region``, ``Diagnosis`` (``to_dict``: the JSON contract)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..kinematics import Kinematics


@dataclass(frozen=True)
class DiagnosisOptions:
    """Every threshold of the diagnosis. ``bic_threshold``: accept only ΔBIC < -threshold (10 = "very strong",
    Kass & Raftery)."""
    bic_threshold: float = 10.0
    cv_folds: int = 5
    cv_min_t: float = 2.0             # paired t of the per-point CV error decrease
    min_excess_fraction: float = 0.05  # an accepted effect removes at least this share of the CV excess over the floor
    group_bic_margin: float = 6.0     # a further group (joint, harmonic, term) of a candidate must lower BIC this much
    max_effects: int = 6
    harmonics: tuple[int, ...] = (1, 2, 3, 4)
    compliance_joints: tuple[int, ...] = (2, 3)
    thermal_zero_joints: tuple[int, ...] = (1, 2, 3)
    tau_grid_h: tuple[float, ...] = (0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0, 5.0)
    shape_grid: tuple[float, ...] = (0.5, 0.7, 1.0, 1.4, 2.0)   # stretched-exponential warm-up exponents
    outlier_sigma: float = 5.0
    absorbed_limit: float = 0.95      # candidates absorbed beyond this by geometry are undiagnosable
    region_alpha: float = 0.01        # family-wise, Bonferroni over the regions of a stage
    region_min_ratio: float = 1.2     # a flagged region is at least this much above the floor
    structure_z: float = 4.0
    structure_min_fraction: float = 0.33
    neighbours: int = 10
    permutations: int = 200
    max_regions: int = 12
    split_alpha: float = 1e-4         # reach-split consistency: parameters of near and far halves must agree ...
    split_min_ratio: float = 0.25     # ... to within this share of the effect's visible displacement
    seed: int = 0
    # gates of the selection
    overlap_min: float = 0.5          # cos of the smallest principal angle above which two effects overlap (one class)
    cv_excess_min_share: float = 0.25  # CV excess over the floor counted as at least this share of the CV MSE
    cv_param_inflation: float = 1.25  # floor inflation per parameter share (parameter error, K-1 of K folds)
    outlier_max_fraction: float = 0.1  # more gross outliers than this share: none set aside (structure, not outliers)
    backward_repeats: int = 2         # further backward passes once effects were dropped
    # can the data reveal an effect (metadata checks of the candidates)
    gear_min_span_deg: float = 20.0   # a joint covering less cannot show a cyclic error
    backlash_min_side: int = 5        # approaches from each side needed on a joint, at least ...
    backlash_min_side_fraction: float = 0.05   # ... and this share of the calibration rows
    lag_min_move_std_deg: float = 1.0  # a joint whose moves vary less cannot show a read-back lag
    lag_direct_min_t: float = 5.0     # commanded vs read-back joints: lag significant at this |t| ...
    lag_direct_min_deg_per_deg: float = 2e-5   # ... and at least this large
    temp_min_span_c: float = 0.2      # logged temperatures must span this much to profile a warm-up
    time_min_span_s: float = 900.0    # timestamps must span this much to profile a drift
    thermal_min_link_mm: float = 50.0  # links shorter than this get no thermal growth column
    coupling_min_off_axis_mm: float = 20.0   # SMR closer to the J6 axis: note that J6 coupling is nearly invisible
    nest_alpha: float = 1e-3          # reference nests: drift detected below this p value ...
    nest_ruled_out_ratio: float = 1.5  # ... ruled out when its upper bound is below this x the noise floor
    # physical plausibility: largest credible |parameter| of each candidate
    max_joint_deflection_rad: float = 2e-3   # implied joint deflection of gear, backlash and zero-drift terms
    gear_max_rad: float = 1.5e-3      # amplitude of each harmonic term
    backlash_max_rad: float = 3e-3    # full backlash width
    lag_max: float = 5e-3             # read-back lag (rad per rad of move)
    growth_max: float = 1e-3          # thermal growth (relative length)
    zero_drift_max_rad: float = 2e-3  # thermal zero drift of a joint
    registration_max_mm: float = 1.0  # registration drift: translation ...
    registration_max_rad: float = 5e-4   # ... and rotation over the run
    coupling_max: float = 0.02        # axis coupling (rad per rad)
    # where it lies and what is left over
    region_min_points: int = 5        # regions (and each approach side) with fewer points are not tested
    floor_f_alpha: float = 1e-3       # repeat floor: F test of the final scatter against the floor at this level
    chi2_sigmas: float = 3.0          # specs floor: chi2/dof limit 1 + this x sqrt(2/dof)
    scatter_excess_ratio: float = 1.12   # final CV RMS above this x the (inflated) floor counts as excess scatter
    partial_share: float = 0.5        # accepted effects removing less of the excess: attribution is partial
    floor_overestimate_ratio: float = 0.8   # final CV RMS below this x a repeat floor: the floor is overestimated


@dataclass(frozen=True, eq=False)
class DiagnosisInput:
    """One dataset. Rows in measurement order (calibration and test rows; repeats used for the floor are not
    passed). ``q_rad`` (N, n), ``p_mm`` (N, 3) tracker frame, ``cov_mm2`` (N, 3, 3) measurement covariance
    (tracker + robot repeatability), ``calib``/``test`` (N,) bool. Metadata (each optional): ``t_s`` (N,),
    ``temp_c`` (N,), ``payload_kg`` (N,), ``approach`` (N, n) sign of each joint's last motion.
    ``noise_floor_dof``: degrees of freedom (points) of a floor measured from repeats, so that tests against the
    floor account for its own uncertainty."""
    kin: Kinematics
    q_rad: np.ndarray
    p_mm: np.ndarray
    cov_mm2: np.ndarray
    calib: np.ndarray
    test: np.ndarray
    noise_floor_mm: float
    noise_floor_source: str = "specs"
    noise_floor_dof: int | None = None     # repeats: sum over repeated poses of (count - 1); None = specs
    t_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    approach: np.ndarray | None = None
    move_rad: np.ndarray | None = None           # (N, n) signed last move of each joint (rad), None: from row order
    prev_move_rad: np.ndarray | None = None      # (N, n) the move before it
    qc_rad: np.ndarray | None = None             # (N, n) commanded joints next to the read-back q_rad
    q_read_rad: np.ndarray | None = None         # (N, n) read-back joints when q_rad are not (commanded chosen)
    baseline: Kinematics | None = None           # the best geometric model (reprocess's kinematic stage)
    baseline_identified: tuple[str, ...] | None = None   # its identified parameter names
    nests: "NestReadings | None" = None
    order: np.ndarray | None = None              # (N,) position of each row in the measurement sequence
    payload_rated_kg: float | None = None

    def meta(self) -> dict:
        move, prev = self.move_rad, self.prev_move_rad
        if move is None:
            move, prev = moves_from_order(self.q_rad)
        return {"t_s": self.t_s, "temp_c": self.temp_c, "payload_kg": self.payload_kg, "approach": self.approach,
                "move": move, "prev_move": prev, "qc": self.qc_rad, "payload_rated_kg": self.payload_rated_kg,
                "q_read": self.q_read_rad}


@dataclass(frozen=True, eq=False)
class NestReadings:
    """Reference-nest readings in measurement order: ``p_mm`` (M, 3) tracker frame, ``nest_id`` (M,),
    ``t_s`` (M,) or None, ``order`` (M,) position in the measurement sequence (any monotone index)."""
    p_mm: np.ndarray
    nest_id: tuple[str, ...]
    t_s: np.ndarray | None
    order: np.ndarray


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
                "test_rms_before_mm": _f(self.test_rms_before_mm), "test_rms_after_mm": _f(self.test_rms_after_mm),
                "evidence": _plain(self.evidence)}


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
        d = {"description": self.description, "rms_mm": _f(self.rms_mm), "floor_mm": _f(self.floor_mm),
             "ratio": _f(self.rms_mm / self.floor_mm) if self.floor_mm > 0 else None, "n": int(self.n),
             "kind": self.kind, "stage": self.stage, "p_value": _f(self.p_value)}
        d.update(_plain(self.extra))
        return d


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of ``diagnose``. ``to_dict`` gives the JSON contract of issue 7 (plus detail keys)."""
    noise_floor_mm: float
    noise_floor_source: str
    baseline_test_rms_mm: float
    final_test_rms_mm: float
    unexplained: bool
    findings: tuple[Finding, ...]
    where: tuple[Region, ...]
    undiagnosable: tuple[dict, ...]
    evaluation: str                 # "test" | "cv" (no test rows: cross-validated calibration residuals)
    structure: dict
    maps: dict
    notes: tuple[str, ...]
    n_calib: int
    n_test: int
    outliers: tuple[int, ...]       # row indices set aside as gross outliers
    kinematics: Kinematics
    accepted: tuple                 # ((Group, params), ...) of the final model
    stages: tuple[dict, ...]        # test/CV RMS after each accepted step (step 0 = geometric)

    @property
    def accepted_effects(self) -> tuple[str, ...]:
        return tuple(f.effect for f in self.findings if f.accepted)

    def to_dict(self) -> dict:
        return {
            "noise_floor_mm": _f(self.noise_floor_mm), "noise_floor_source": self.noise_floor_source,
            "baseline_test_rms_mm": _f(self.baseline_test_rms_mm), "final_test_rms_mm": _f(self.final_test_rms_mm),
            "unexplained": bool(self.unexplained),
            "findings": [f.to_dict() for f in self.findings],
            "where": [r.to_dict() for r in self.where],
            "evaluation": self.evaluation, "n_calib": self.n_calib, "n_test": self.n_test,
            "outliers": len(self.outliers), "undiagnosable": _plain(list(self.undiagnosable)),
            "structure": _plain(self.structure), "stages": _plain(list(self.stages)), "notes": list(self.notes),
            "maps": _plain(self.maps),
        }


def _f(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _plain(x):
    """JSON-ready copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return _f(float(x))
    return x


def moves_from_order(q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(last move, the move before) per row and joint (N, n) rad, from rows in measurement order."""
    q = np.asarray(q_rad, float)
    move = np.zeros_like(q)
    move[1:] = np.diff(q, axis=0)
    prev = np.zeros_like(q)
    prev[1:] = move[:-1]
    return move, prev
