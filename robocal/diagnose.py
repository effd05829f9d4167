"""Sim-to-real gap diagnosis: where the residual of the best geometric model lies, which unmodelled effect
causes it and how far it shrinks once that effect is added (effects.md §5-6, "RANCE").

Pure numerics: arrays in, dataclasses out. Steps (``diagnose``):

1. **Base fit**: registration + identifiability + Levenberg-Marquardt of the complete geometric model
   (``robocal.identify.calibrate``); gross outliers (> 5 robust sigma) are set aside.
2. **Candidates** (``build_candidates``): each library effect as groups of regressor columns, a joint-space
   basis ``dq`` (rad per unit parameter, mapped to the SMR by the joint Jacobian) and/or a tracker-frame basis
   ``dp`` (mm per unit parameter). Forms are deliberately more general than the simulator's: compliance from the
   gravity lever arms of every downstream joint point (any lumped-mass model on the link lines), cyclic errors
   with harmonics 1-4 chosen by the data, thermal growth per link length with a warm-up time constant scanned
   0.25-5 h (or the logged temperature), registration drift with a linear or settling profile.
   Metadata checks decide first whether an effect *can* show in these data (timestamps, approach changes,
   two payloads, joint range, SMR off the J6 axis); absorption by geometry is measured on the regressors.
3. **Scoring** on the calibration set, linearised at the current fit: every regressor is orthogonalised against
   the geometric Jacobian and the effects already accepted (so only the non-absorbed part counts); the groups of
   a candidate are chosen greedily by BIC; score = ΔBIC (n = 3 x points, RSS-based so it does not trust the
   noise model's scale), extra-sum-of-squares F test, blocked K-fold cross-validation (by pose; contiguous time
   blocks for time effects), and the physical plausibility of the fitted values.
4. **Forward selection, strongest evidence first**: accept the candidate with the lowest ΔBIC that passes the
   named gates (ΔBIC < -10, absorption, veto by a direct comparison, blocked CV, physical plausibility judged on
   physical parameters such as stiffness or lag, the saturation test backlash vs read-back lag, the nested test
   compliance vs payload deflection); refit geometry + accepted effects with the exact (nonlinear) forward model;
   repeat until no candidate passes. Then the survivors must pass again in the final model: an effect-agnostic
   reach-split consistency check, CV against the model without them, ΔBIC of removal; groups no longer needed are
   pruned. A better-scored candidate rejected by a gate whose visible subspace overlaps the winner's, and
   near-ties with overlapping subspaces, are reported as one confusable class with the separating experiment.
5. **Where**: held-out test residuals and cross-validated calibration residuals of the geometric model (and of
   the final model) mapped over workspace cells, each joint's range, base axes, time, approach direction and
   payload; regions whose RMS exceeds the noise floor significantly (chi-square, Bonferroni) are named.
6. **Unexplained**: a k-nearest-neighbour permutation test for residual structure left in the final model
   (joint space, workspace, time and each single input); significant structure above a third of the floor is
   reported as ``unexplained`` together with where it lies.

Joint numbers are 1-based everywhere in the output.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy import stats
from scipy import sparse
from scipy.spatial import cKDTree

from .effects import G_MM_S2
from .frames import skew
from .identify import CalibrationOptions, calibrate
from .kinematics import Kinematics, ParamLayout, apply_update, chain, identification_jacobian

EFFECT_NAMES = ("joint_compliance", "payload_deflection", "gear_cyclic", "backlash", "readback_lag", "thermal_drift",
                "axis_coupling", "registration_drift")
TIME_EFFECTS = ("thermal_drift", "registration_drift")
REMEDY = {
    "joint_compliance": "measure with two payloads and wide J2/J3 coverage including upright poses",
    "payload_deflection": "measure with a second payload (e.g. none and the rated load), alternating in blocks",
    "gear_cyclic": "cover the joint's whole range; dense single-joint sweeps (0.05-0.2 deg) for motor-rate terms",
    "backlash": "approach the poses from random, recorded directions (or paired +/- approaches)",
    "readback_lag": "log the commanded joints next to the read-back ones (qc1..qcn) and vary the size of the moves",
    "thermal_drift": "log timestamps (and temperatures) from a cold start, poses in random order over >= 2 h",
    "axis_coupling": "mount the SMR >= 50 mm off the J6 axis and cover J4/J5 widely",
    "registration_drift": "log timestamps and re-measure 3-4 floor nests every 10-15 min",
}
ELASTIC_CLASS = ("gravity-elastic class: joint compliance, link bending and base compliance give nearly the same "
                 "position signature with one SMR (orientation data or loads in different directions separate them)")


# ============================================================================ inputs, options, outputs
@dataclass(frozen=True)
class DiagnosisOptions:
    """Thresholds. ``bic_threshold``: accept only ΔBIC < -threshold (10 = "very strong", Kass & Raftery)."""
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


# ============================================================================ candidates
@dataclass(frozen=True, eq=False)
class Group:
    """Columns of one candidate sub-model: joint-space basis ``dq`` (N, n, k) rad per unit parameter and/or
    tracker-frame basis ``dp`` (N, 3, k) mm per unit parameter. ``limit`` (k,) max plausible |parameter|;
    ``dq_limit`` max plausible implied joint deflection over the data (rad)."""
    label: str
    joints: tuple[int, ...]
    names: tuple[str, ...]
    dq: np.ndarray | None = None
    dp: np.ndarray | None = None
    limit: np.ndarray | float = np.inf
    dq_limit: float = 2e-3
    u: np.ndarray | None = None          # (N,) per-point scale of ``base`` (time profiles): X = u * X_base
    base: "Group | None" = None

    @property
    def k(self) -> int:
        return len(self.names)

    def scaled(self, u: np.ndarray) -> "Group":
        """This group times a per-point profile u (N,): its regressor is u times this one's (exactly, since the
        whitening is per point), which lets the scoring whiten the base once for all profiles."""
        return Group(self.label, self.joints, self.names, None if self.dq is None else u[:, None, None] * self.dq,
                     None if self.dp is None else u[:, None, None] * self.dp, self.limit, self.dq_limit, u, self)


@dataclass(frozen=True, eq=False)
class Profile:
    """One variant of a candidate (time effects: one per time profile)."""
    label: str
    groups: tuple[Group, ...]


@dataclass(frozen=True, eq=False)
class Candidate:
    name: str
    joints: tuple[int, ...]
    profiles: tuple[Profile, ...] = ()
    reason: str = ""                    # why the data cannot reveal it ("" = diagnosable)
    notes: tuple[str, ...] = ()
    extends: bool = False               # the unselected groups of an accepted candidate
    veto: str = ""                      # a gate that rules it out whatever the fit says (e.g. direct comparison)
    info: dict = field(default_factory=dict)   # extra evidence (direct comparisons, nest drift)

    @property
    def key(self) -> str:
        return f"{self.name}:J{self.joints[0]}" if self.name == "gear_cyclic" else self.name

    @property
    def time_effect(self) -> bool:
        return self.name in TIME_EFFECTS

    @property
    def scan(self) -> int:
        """Extra parameters spent on choosing the profile: the time constant and the shape of a warm-up curve
        count as one each."""
        return 2 if len(self.profiles) > 2 else (1 if len(self.profiles) == 2 else 0)

    def rest(self, profile: "Profile", used) -> "Candidate | None":
        """The same candidate restricted to ``profile``'s groups not in ``used`` (None if nothing is left)."""
        left = tuple(g for g in profile.groups if all(g is not u for u in used))
        return Candidate(self.name, self.joints, (Profile(profile.label, left),), notes=self.notes,
                         extends=True, info=self.info) if left else None


def _torque_per_kg(axis_j, origin_j, P):
    """Gravity torque about a joint axis of 1 kg at P (N, 3) mm, N·m/kg; gravity is -z of the base frame."""
    h = np.cross(np.array([0.0, 0.0, 1.0]), axis_j)
    return -G_MM_S2 * np.einsum("nk,nk->n", h, P - origin_j) / 1000.0


def _independent(cols: np.ndarray, rows: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """Indices of columns of cols (N, m) that are linearly independent on ``rows`` (greedy Gram-Schmidt)."""
    A = cols[rows]
    keep, Q = [], np.zeros((len(rows), 0))
    for j in range(A.shape[1]):
        c = A[:, j]
        nrm = np.linalg.norm(c)
        if nrm < 1e-12:
            continue
        c = c / nrm
        r = c - Q @ (Q.T @ c)
        if np.linalg.norm(r) > tol:
            keep.append(j)
            Q = np.column_stack([Q, r / np.linalg.norm(r)])
    return np.array(keep, int)


def gravity_levers(kin: Kinematics, q_rad: np.ndarray, joint: int) -> tuple[np.ndarray, list[str]]:
    """Gravity torque per kg (N, m) about ``joint`` (1-based) of every downstream joint point, the flange and a
    point beside the next link: any lumped mass fixed on those links loads the joint by a combination of them."""
    c = chain(kin, q_rad, full=False)
    n = kin.n
    j = joint - 1
    flange = c.T_base_flange[:, :3, 3]
    pts = [(f"o{i + 1}", c.origin[:, i]) for i in range(j + 1, n)] + [("flange", flange)]
    nxt = c.origin[:, j + 1] if j + 1 < n else flange
    pts.append(("lateral", c.origin[:, j] + np.cross(c.axis[:, j], nxt - c.origin[:, j])))
    cols = np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], P) for _, P in pts], axis=1)
    return cols, [name for name, _ in pts]


def payload_levers(kin: Kinematics, q_rad: np.ndarray, joint: int, payload_kg: np.ndarray) -> np.ndarray:
    """Payload gravity torque (N, 2) N·m about ``joint`` for a payload at the flange and 100 mm along the tool
    axis (any centre of mass on the tool axis is a combination of the two)."""
    c = chain(kin, q_rad, full=False)
    j = joint - 1
    flange = c.T_base_flange[:, :3, 3]
    tip = flange + 100.0 * c.T_base_flange[:, :3, 2]
    return np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], P) for P in (flange, tip)], axis=1) \
        * np.asarray(payload_kg, float)[:, None]


def arm_mass_kg(kin: Kinematics) -> float:
    """Moving mass of an arm of this size (kg): about 25 kg at 0.58 m reach, growing with reach^2.5 (the size
    law of industrial 6-axis arms from 0.5 to 3 m reach)."""
    return 25.0 * (robot_reach_mm(kin) / 580.0) ** 2.5


def robot_reach_mm(kin: Kinematics) -> float:
    """Reach from the shoulder: sum of the link lengths after J1 (mm)."""
    return float(np.sum(np.hypot(kin.a_mm[1:], kin.d_mm[1:])) + np.linalg.norm(kin.p_flange_smr_mm))


def physical_torque_nm(kin: Kinematics, q_rad: np.ndarray, payload_kg: np.ndarray | None, arm: bool = True
                       ) -> np.ndarray:
    """Gravity torque (N, n) N*m about every joint of a physical lumped-mass model from the robot's size: the
    moving mass (``arm_mass_kg``) shared over the links after J1 in proportion to their lengths, each at its
    link's midpoint, plus the payload at the flange. Gravity is -z of the base frame."""
    c = chain(kin, q_rad, full=False)
    N, n = np.shape(q_rad)
    o = np.concatenate([c.origin, c.T_base_flange[:, None, :3, 3]], axis=1)
    mid = 0.5 * (o[:, :-1] + o[:, 1:])
    length = np.hypot(kin.a_mm, kin.d_mm)
    length[0] = 0.0
    m = arm_mass_kg(kin) * length / max(float(length.sum()), 1e-9) if arm else np.zeros(n)
    pay = np.zeros(N) if payload_kg is None else np.asarray(payload_kg, float)
    tau = np.zeros((N, n))
    for j in range(n):
        t_links = np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], mid[:, i]) for i in range(j, n)], axis=1)
        tau[:, j] = t_links @ m[j:] + _torque_per_kg(c.axis[:, j], c.origin[:, j], o[:, -1]) * pay
    return tau


def moves_from_order(q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(last move, the move before) per row and joint (N, n) rad, from rows in measurement order."""
    q = np.asarray(q_rad, float)
    move = np.zeros_like(q)
    move[1:] = np.diff(q, axis=0)
    prev = np.zeros_like(q)
    prev[1:] = move[:-1]
    return move, prev


def direct_lag(q_read_rad: np.ndarray, qc_rad: np.ndarray, move_rad: np.ndarray, prev_rad: np.ndarray) -> dict:
    """Read-back minus commanded joints regressed per joint on [1, last move, move before]: the lag (deg/deg),
    its t value, the memory term and the correlation of the difference with the move."""
    d = np.asarray(q_read_rad, float) - np.asarray(qc_rad, float)
    out = {}
    for j in range(d.shape[1]):
        ok = np.isfinite(d[:, j]) & np.isfinite(move_rad[:, j])
        A = np.column_stack([np.ones(ok.sum()), move_rad[ok, j], prev_rad[ok, j]])
        y = d[ok, j]
        if ok.sum() < 10 or np.ptp(move_rad[ok, j]) <= 0:
            continue
        beta, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ beta
        s2 = float(r @ r) / max(len(y) - 3, 1)
        cov = s2 * np.linalg.pinv(A.T @ A)
        se = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        corr = float(np.corrcoef(y, move_rad[ok, j])[0, 1]) if np.std(y) > 0 else 0.0
        out[j + 1] = {"lag_deg_per_deg": float(beta[1]), "t": float(beta[1] / se[1]),
                      "memory_deg_per_deg": float(beta[2]), "t_memory": float(beta[2] / se[2]),
                      "offset_deg": float(np.degrees(beta[0])), "std_deg": float(np.degrees(np.std(y))),
                      "correlation_with_move": corr}
    return out


def _dq_group(label, joint_cols: dict, names, n, N, joints, **kw) -> Group:
    """Group whose columns act on single joints: joint_cols {joint (1-based): (N, k_j) array}."""
    k = sum(a.shape[1] for a in joint_cols.values())
    dq = np.zeros((N, n, k))
    at = 0
    for jt, a in joint_cols.items():
        dq[:, jt - 1, at:at + a.shape[1]] = a
        at += a.shape[1]
    return Group(label, tuple(joints), tuple(names), dq=dq, **kw)


def _payload_varies(payload, rows) -> bool:
    if payload is None:
        return False
    values = np.unique(np.round(np.asarray(payload, float)[rows], 3))
    return len(values) >= 2


def _compliance(kin, q, meta, rows, opt, payload_only: bool) -> Candidate:
    N, n = q.shape
    payload = meta.get("payload_kg")
    varies = _payload_varies(payload, rows)
    name = "payload_deflection" if payload_only else "joint_compliance"
    joints = tuple(j for j in opt.compliance_joints if 2 <= j <= n)
    if payload_only and not varies:
        why = "no payload logged" if payload is None else "one payload only"
        return Candidate(name, joints, reason=f"{why}: a payload-dependent deflection cannot be told from "
                                              "geometry and link-mass compliance")
    groups, shape = [], []
    tau = physical_torque_nm(kin, q, None if payload is None else np.asarray(payload, float), arm=not payload_only)
    for jt in joints:
        groups.append(_dq_group(f"J{jt}", {jt: tau[:, jt - 1:jt]}, (f"c{jt}",), n, N, (jt,), dq_limit=np.inf))
        parts, names = [], []
        if not payload_only:
            lev, labels = gravity_levers(kin, q, jt)
            parts.append(lev)
            names += [f"c{jt}_{lb}" for lb in labels]
        if varies:
            parts.append(payload_levers(kin, q, jt, payload))
            names += [f"c{jt}_payload_flange", f"c{jt}_payload_tool"]
        cols = np.concatenate(parts, axis=1)
        t = tau[rows, jt - 1]
        cols = cols - np.outer(tau[:, jt - 1], cols[rows].T @ t / max(float(t @ t), 1e-300))   # beyond the physical
        keep = _independent(cols, rows, 1e-2)
        if len(keep):
            shape.append(_dq_group(f"J{jt} mass distribution", {jt: cols[:, keep]}, tuple(names[i] for i in keep),
                                   n, N, (jt,), dq_limit=np.inf))
    groups += shape
    notes = [ELASTIC_CLASS] if not payload_only else []
    if not payload_only and not varies:
        notes.append("one payload only: compliance is partly confounded with geometry (log a second payload)")
    return Candidate(name, joints, (Profile("gravity torque", tuple(groups)),), notes=tuple(notes),
                     info={"torque_nm": tau, "stiffness_min_nm_per_rad": stiffness_floor_nm_per_rad(kin)})


def stiffness_floor_nm_per_rad(kin: Kinematics) -> float:
    """Lowest plausible joint stiffness of an arm of this size (N*m/rad): 2e4 x (reach in m)^3, about ten times
    softer than the main axes of industrial arms (stiffness grows with the cube of the size)."""
    return 2e4 * (robot_reach_mm(kin) / 1000.0) ** 3


def _gear(kin, q, joint, rows, opt) -> Candidate:
    N, n = q.shape
    qj = q[rows, joint - 1]
    span = np.degrees(qj.max() - qj.min())
    if span < 20.0:
        return Candidate("gear_cyclic", (joint,), reason=f"J{joint} covers only {span:.0f} deg: a cyclic error "
                                                         "cannot be told from its zero offset")
    groups = []
    for h in opt.harmonics:
        cols = np.stack([np.sin(h * q[:, joint - 1]), np.cos(h * q[:, joint - 1])], axis=1)
        groups.append(_dq_group(f"h{h}", {joint: cols}, (f"sin{h}", f"cos{h}"), n, N, (joint,), limit=1.5e-3))
    return Candidate("gear_cyclic", (joint,), (Profile("harmonics", tuple(groups)),))


def _backlash(kin, q, meta, rows) -> Candidate:
    N, n = q.shape
    s = meta.get("approach")
    joints = tuple(range(1, n + 1))
    if s is None:
        return Candidate("backlash", joints, reason="no approach directions in the data")
    s = np.asarray(s, float)
    groups, constant = [], []
    for j in joints:
        sj = s[rows, j - 1]
        if min(np.sum(sj > 0), np.sum(sj < 0)) < max(5, 0.05 * len(rows)):
            constant.append(j)
            continue
        groups.append(_dq_group(f"J{j}", {j: 0.5 * s[:, j - 1:j]}, (f"b{j}",), n, N, (j,), limit=3e-3))
    if not groups:
        return Candidate("backlash", joints, reason="approach directions never change (every joint is reached "
                                                    "from the same side)")
    notes = (f"approach direction constant on J{', J'.join(map(str, constant))}",) if constant else ()
    return Candidate("backlash", tuple(g.joints[0] for g in groups), (Profile("approach", tuple(groups)),),
                     notes=notes)


def _readback_lag(kin, q, meta, rows, opt) -> Candidate:
    """Read-back lag: the reported joint is off by lambda x (signed last move) [+ mu x (move before)]; the model
    input is corrected by dq = -lambda move (parameter -lambda, rad/rad). With commanded joints the difference is
    measured directly and decides which joints can carry it."""
    N, n = q.shape
    move, prev, qc = meta.get("move"), meta.get("prev_move"), meta.get("qc")
    joints = tuple(j for j in range(1, n + 1) if np.std(move[rows, j - 1]) > np.radians(1.0))
    if not joints:
        return Candidate("readback_lag", tuple(range(1, n + 1)), reason="the joints hardly move between points")
    veto, direct = "", {}
    if qc is not None:
        qcm, qcp = moves_from_order(qc) if meta.get("move_cmd") is None else (meta["move_cmd"], meta["prev_cmd"])
        direct = direct_lag(q if meta.get("q_read") is None else meta["q_read"], qc, qcm, qcp)
        sig = tuple(j for j in joints if j in direct and abs(direct[j]["t"]) >= 5.0
                    and abs(direct[j]["lag_deg_per_deg"]) >= 2e-5)
        if not sig:
            veto = ("commanded and read-back joints agree: no lag proportional to the move (direct comparison, "
                    "|t| < 5 on every joint)")
        else:
            joints = sig
    kw = {"limit": 5e-3, "dq_limit": np.inf}          # judged on the lag itself (deg/deg), not on move x lag
    groups = [_dq_group(f"J{j}", {j: move[:, j - 1:j]}, (f"lag{j}",), n, N, (j,), **kw) for j in joints]
    groups += [_dq_group(f"J{j} memory", {j: prev[:, j - 1:j]}, (f"lag{j}_memory",), n, N, (j,), **kw)
               for j in joints]
    return Candidate("readback_lag", joints, (Profile("signed last move", tuple(groups)),), veto=veto,
                     info={"direct_comparison": direct} if direct else {})


def _time_profiles(meta, rows, opt) -> tuple[list[tuple[str, np.ndarray]], str]:
    """[(label, u (N,) in [0, 1])] time profiles, or a reason why none exists."""
    t, temp = meta.get("t_s"), meta.get("temp_c")
    out = []
    if temp is not None:
        temp = np.asarray(temp, float)
        rise = temp - temp[rows].min()
        if np.ptp(temp[rows]) >= 0.2:
            out.append(("temperature", rise / np.max(np.abs(rise[rows]))))
    if t is not None:
        t = np.asarray(t, float)
        span = np.ptp(t[rows])
        if span >= 900.0:
            t0 = t - t[rows].min()
            out.append(("linear in time", t0 / np.max(t0[rows])))
            for beta in opt.shape_grid:
                for tau in opt.tau_grid_h:
                    u = 1.0 - np.exp(-(np.maximum(t0, 0.0) / (tau * 3600.0)) ** beta)
                    shape = "" if beta == 1.0 else f", shape {beta:g}"
                    out.append((f"warm-up 1-exp(-(t/tau)^b) tau {tau:g} h{shape}", u / np.max(u[rows])))
        elif not out:
            return [], f"the data span only {span / 60:.0f} min: too short to reveal drift"
    if not out:
        return [], "no timestamps or temperatures in the data"
    return out, ""


def _thermal(kin, q, meta, J, layout, rows, opt) -> Candidate:
    """Warm-up u(t) x {uniform growth of every link length, growth of single links, zero drift of J2/J3}.
    The base-column length d1 alone is left out of the single-link groups: its growth is a rigid vertical
    drift, which is registration drift's signature; it enters through the uniform growth."""
    N, n = q.shape
    profiles, why = _time_profiles(meta, rows, opt)
    joints = tuple(j for j in opt.thermal_zero_joints if j <= n)
    if why:
        return Candidate("thermal_drift", joints, reason=why)
    lengths = [(c, f"{'da'[k - 1]}{i + 1}", (kin.d_mm if k == 1 else kin.a_mm)[i])
               for c, i, k in layout.joint_cols if k in (1, 2) and abs((kin.d_mm if k == 1 else kin.a_mm)[i]) > 50.0]
    uniform = sum(J[:, :, c] * L for c, _, L in lengths)
    single = [(c, name, L) for c, name, L in lengths if name != "d1"]
    bases = [Group("uniform growth", (), ("growth_all",), dp=uniform[:, :, None], limit=1e-3)]
    bases += [Group(f"growth {name}", (), (f"growth_{name}",), dp=(J[:, :, c] * L)[:, :, None], limit=1e-3)
              for c, name, L in single]
    bases += [_dq_group(f"zero J{j}", {j: np.ones((N, 1))}, (f"zero_drift{j}",), n, N, (j,), limit=2e-3)
              for j in joints]
    out = [Profile(label, tuple(b.scaled(u) for b in bases)) for label, u in profiles]
    return Candidate("thermal_drift", joints, tuple(out))


def _registration(kin, q, meta, p_model, rows, opt) -> Candidate:
    drift = meta.get("nest_drift")
    info = {"nest_drift": drift} if drift else {}
    if drift and drift["ruled_out"]:
        return Candidate("registration_drift", (), veto=f"ruled out by the reference nests: {drift['summary']}",
                         info=info)
    if meta.get("t_s") is None:
        if drift and drift["detected"]:              # no timestamps: the measurement order carries the time
            x = np.asarray(meta["order"], float)
            x = (x - x[rows].min()) / max(np.ptp(x[rows]), 1e-9)
            profiles = [("linear in measurement order", x), ("quadratic in measurement order", x**2)]
        else:
            return Candidate("registration_drift", (), reason="no timestamps in the data"
                             + ("" if drift else " and no reference nests"), info=info)
    else:
        profiles, why = _time_profiles(meta, rows, opt)
        profiles = [(label, u) for label, u in profiles if label != "temperature"]
        if why or not profiles:
            return Candidate("registration_drift", (), reason=why or "no timestamps in the data", info=info)
    centre = p_model[rows].mean(axis=0)
    screw = np.concatenate([np.broadcast_to(np.eye(3), (len(q), 3, 3)), -skew(p_model - centre)], axis=2)
    names = ("vx", "vy", "vz", "wx", "wy", "wz")
    limit = np.array([1.0, 1.0, 1.0, 5e-4, 5e-4, 5e-4])
    bases = (Group("translation", (), names[:3], dp=screw[:, :, :3], limit=limit[:3]),
             Group("rotation", (), names[3:], dp=screw[:, :, 3:], limit=limit[3:]))
    out = [Profile(label, tuple(b.scaled(u) for b in bases)) for label, u in profiles]
    return Candidate("registration_drift", (), tuple(out), info=info)


def _coupling(kin, q) -> Candidate:
    N, n = q.shape
    if n < 6:
        return Candidate("axis_coupling", (), reason="needs a 6-axis wrist")
    kw = {"limit": 0.02, "dq_limit": 0.02 * np.max(np.abs(q[:, 3:5]))}
    groups = (_dq_group("e56", {6: q[:, 4:5]}, ("e56",), n, N, (5, 6), **kw),
              _dq_group("e46", {6: q[:, 3:4]}, ("e46",), n, N, (4, 6), **kw),
              _dq_group("e45", {5: q[:, 3:4]}, ("e45",), n, N, (4, 5), **kw))
    notes = ()
    off_axis = float(np.hypot(*kin.p_flange_smr_mm[:2]))
    if off_axis < 20.0:
        notes = (f"SMR only {off_axis:.0f} mm off the J6 axis: J6 coupling is nearly invisible",)
    return Candidate("axis_coupling", (4, 5, 6), (Profile("wrist", groups),), notes=notes)


def build_candidates(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, rows: np.ndarray, J: np.ndarray,
                     p_model: np.ndarray, options: DiagnosisOptions = DiagnosisOptions()) -> list[Candidate]:
    """The candidate library evaluated at ``kin`` for all rows; ``rows`` (indices) are the calibration rows
    used to judge whether the metadata vary enough. ``J`` (N, 3, P) identification Jacobian, ``p_model`` (N, 3)."""
    layout = ParamLayout.of(kin)
    n = kin.n
    cands = [_compliance(kin, q_rad, meta, rows, options, False), _compliance(kin, q_rad, meta, rows, options, True)]
    cands += [_gear(kin, q_rad, j, rows, options) for j in range(1, n + 1)]
    cands += [_backlash(kin, q_rad, meta, rows), _readback_lag(kin, q_rad, meta, rows, options), _thermal(kin, q_rad, meta, J, layout, rows, options),
              _coupling(kin, q_rad), _registration(kin, q_rad, meta, p_model, rows, options)]
    return cands


# ============================================================================ the fitting engine
def _whiten(W, x):
    return np.einsum("nij,nj...->ni...", W, x)


def _orth(M: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of M (columns scaled to unit norm first)."""
    if M.shape[1] == 0:
        return np.zeros((M.shape[0], 0))
    nrm = np.linalg.norm(M, axis=0)
    M = M[:, nrm > 1e-300] / nrm[nrm > 1e-300]
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    return U[:, s > tol * max(s[0], 1e-300)] if len(s) else U


def _lstsq_scaled(A, y, rcond=1e-10):
    nrm = np.linalg.norm(A, axis=0)
    nrm[nrm < 1e-300] = 1.0
    x = np.linalg.lstsq(A / nrm, y, rcond=rcond)[0]
    return x / nrm


@dataclass(eq=False)
class _State:
    kin: Kinematics
    groups: list
    theta: np.ndarray
    pred: np.ndarray          # (N, 3) model SMR positions (tracker frame)
    J: np.ndarray             # (N, 3, P) at the effect-shifted joints


class _Engine:
    """Model evaluation, refits and linearised designs over the rows of one dataset."""

    def __init__(self, inp: DiagnosisInput, cols: np.ndarray, fit_rows: np.ndarray, test_rows: np.ndarray):
        self.q, self.p = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float)
        self.L = np.linalg.cholesky(np.asarray(inp.cov_mm2, float))
        self.W = np.linalg.inv(self.L)
        self.cols, self.fit_rows, self.test_rows = cols, fit_rows, test_rows
        self.layout = ParamLayout.of(inp.kin)
        self.joint_cols = [c for c, i, k in self.layout.joint_cols if k == 0]     # d p / d q_i

    # ---------------------------------------------------------------- model
    def predict(self, kin, groups, theta) -> tuple[np.ndarray, np.ndarray]:
        dq = np.zeros_like(self.q)
        dp = np.zeros((len(self.q), 3))
        at = 0
        for g in groups:
            th = theta[at:at + g.k]
            at += g.k
            if g.dq is not None:
                dq += g.dq @ th
            if g.dp is not None:
                dp += g.dp @ th
        p, J = identification_jacobian(kin, self.q + dq)
        return p + dp, J

    def regressor(self, J, kin, g: Group) -> np.ndarray:
        """Tracker-frame displacement per unit parameter (N, 3, k) mm."""
        X = np.zeros((len(self.q), 3, g.k))
        if g.dq is not None:
            X += np.einsum("nij,njk->nik", J[:, :, self.joint_cols], g.dq)
        if g.dp is not None:
            X += g.dp
        return X

    def wflat(self, X, rows) -> np.ndarray:
        """Whitened (3m, k) rows of an (N, 3, k) or (N, 3) array."""
        Xw = _whiten(self.W[rows], X[rows])
        return Xw.reshape(3 * len(rows), -1) if Xw.ndim == 3 else Xw.reshape(-1)

    def design(self, st: _State, rows, extra=()) -> np.ndarray:
        parts = [self.wflat(st.J[:, :, self.cols], rows)]
        parts += [self.wflat(self.regressor(st.J, st.kin, g), rows) for g in list(st.groups) + list(extra)]
        return np.concatenate(parts, axis=1)

    def fit(self, kin, groups, theta0=None, iters: int = 8) -> _State:
        """Gauss-Newton on the calibration rows with the exact forward model (geometry + effects)."""
        groups = list(groups)
        k = sum(g.k for g in groups)
        theta = np.zeros(k) if theta0 is None else np.concatenate([theta0, np.zeros(k - len(theta0))])
        rows = self.fit_rows
        nc = len(self.cols)
        full = np.zeros(self.layout.size)
        for _ in range(iters):
            pred, J = self.predict(kin, groups, theta)
            st = _State(kin, groups, theta, pred, J)
            A = self.design(st, rows)
            r = self.wflat(self.p - pred, rows)
            nrm = np.linalg.norm(A, axis=0)
            nrm[nrm < 1e-300] = 1.0
            dx_s = np.linalg.lstsq(A / nrm, r, rcond=1e-10)[0]
            dx = dx_s / nrm
            full[:] = 0.0
            full[self.cols] = dx[:nc]
            kin = apply_update(kin, full)
            theta = theta + dx[nc:]
            if np.linalg.norm(A @ dx) < 1e-4:            # whitened units: far below one noise sigma
                break
        pred, J = self.predict(kin, groups, theta)
        return _State(kin, groups, theta, pred, J)

    # ---------------------------------------------------------------- evaluation
    def resid(self, st: _State) -> np.ndarray:
        return self.p - st.pred

    def test_rms(self, st: _State) -> float:
        if len(self.test_rows) == 0:
            return float("nan")
        r = self.resid(st)[self.test_rows]
        return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))

    def folds(self, by_time: bool, t, K: int, seed: int) -> list[np.ndarray]:
        """K folds of positions into fit_rows: contiguous time blocks or a seeded random partition of poses."""
        m = len(self.fit_rows)
        K = max(2, min(K, m // 10))
        if by_time and t is not None:
            order = np.argsort(np.asarray(t)[self.fit_rows], kind="stable")
        else:
            order = np.random.default_rng(seed).permutation(m)
        return np.array_split(order, K)

    def cv_errors(self, A: np.ndarray, y: np.ndarray, folds) -> np.ndarray:
        """Cross-validated whitened errors (m, 3) of the linear model y ~ A over point folds."""
        m = len(y) // 3
        e = np.zeros((m, 3))
        for f in folds:
            f = np.sort(f)
            train = np.ones(m, bool)
            train[f] = False
            tr = np.repeat(train, 3)
            beta = _lstsq_scaled(A[tr], y[tr])
            te = np.repeat(~train, 3)
            e[f] = (y[te] - A[te] @ beta).reshape(-1, 3)
        return e

    def to_mm(self, e_w: np.ndarray, rows) -> np.ndarray:
        return np.einsum("nij,nj->ni", self.L[rows], e_w)


def _rms(r) -> float:
    r = np.asarray(r, float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan")


# ============================================================================ scoring
@dataclass(eq=False)
class _Score:
    cand: Candidate
    profile: Profile | None = None
    groups: tuple = ()
    delta_bic: float = np.inf
    delta_rss: float = 0.0
    rank: int = 0
    f_stat: float = float("nan")
    p_value: float = 1.0
    absorbed: float = float("nan")         # of the chosen profile
    absorbed_min: float = float("nan")     # of the most visible profile: decides whether it is diagnosable
    U: np.ndarray | None = None            # orthonormal visible subspace of the selected groups
    gamma: np.ndarray | None = None        # linear estimate of the selected parameters
    cv: dict | None = None
    plausible: tuple[bool, str] | None = None
    rejected: str = ""
    backward_delta_bic: float = float("nan")
    split_rejected: str = ""               # dropped as a stand-in for structure outside the library
    pruned: list = field(default_factory=list)     # group labels dropped in the backward pass
    refit_cv_t: float = float("nan")
    steps: list = field(default_factory=list)      # 1-based selection steps that added groups of this effect
    physical: dict = field(default_factory=dict)    # physical parameters (stiffness, lag, half-widths)
    shadowed: list = field(default_factory=list)    # better-scored candidates rejected by a gate, overlapping
    confusable: list = field(default_factory=list)
    extensions: list = field(default_factory=list)

    @property
    def joints(self) -> tuple[int, ...]:
        """Joints of the selected groups (1-based); with none selected, the candidate's joints (time effects:
        none, their groups are link lengths and zero drifts)."""
        js = tuple(sorted({j for g in self.groups for j in g.joints}))
        if js or self.cand.time_effect:
            return js
        return self.cand.joints


def _greedy(blocks, y, rss0, n, lnn, extra, rank_tol=1e-3, margin=0.0):
    """Forward selection of column blocks (each (3m, k), already orthogonal to the base model) by BIC; blocks
    after the first must lower BIC by ``margin``. Returns (chosen indices, ΔBIC, ΔRSS, rank, U)."""
    chosen, S = [], np.zeros((len(y), 0))
    rss, best, r_tot = rss0, 0.0, 0
    look = 2.0 * math.log(len(blocks)) if len(blocks) > 1 else 0.0     # prior 1/G on which group: look-elsewhere
    y_res = y.copy()
    while len(chosen) < len(blocks):
        trial = None
        for i, Z in enumerate(blocks):
            if i in chosen:
                continue
            Zs = Z - S @ (S.T @ Z)
            if Zs.shape[1] == 1:                      # one column: its direction, no SVD needed
                nz = float(np.linalg.norm(Zs))
                Ug = Zs / nz if nz > rank_tol else Zs[:, :0]
            else:
                U, s, _ = np.linalg.svd(Zs, full_matrices=False)
                Ug = U[:, s > rank_tol]
            if Ug.shape[1] == 0:
                continue
            d = float(np.sum((Ug.T @ y_res) ** 2))
            bic = n * math.log(max(rss - d, 1e-300) / rss0) + (r_tot + Ug.shape[1] + extra) * lnn + look
            if trial is None or bic < trial[0]:
                trial = (bic, i, Ug, d)
        if trial is None or trial[0] >= best - (margin if chosen else 0.0):
            break
        best, i, Ug, d = trial
        chosen.append(i)
        S = np.column_stack([S, Ug])
        y_res = y_res - Ug @ (Ug.T @ y_res)
        rss -= d
        r_tot += Ug.shape[1]
    return chosen, best, rss0 - rss, r_tot, S


class _Selector:
    """Forward stepwise selection over the candidates at one dataset."""

    def __init__(self, eng: _Engine, inp: DiagnosisInput, opt: DiagnosisOptions):
        self.eng, self.inp, self.opt = eng, inp, opt
        self.rows = eng.fit_rows
        self.n = 3 * len(self.rows)
        self.lnn = math.log(self.n)

    def base(self, st: _State):
        """Orthonormal basis of the current design and the residual orthogonal to it."""
        A = self.eng.design(st, self.rows)
        Q = _orth(A)
        y = self.eng.wflat(self.eng.resid(st), self.rows)
        return Q, y - Q @ (Q.T @ y), A

    def score(self, cand: Candidate, st: _State, Q, y, Qgeo) -> _Score:
        rss0 = float(y @ y)
        best = _Score(cand)
        absorbed_min = 1.0
        cache: dict[int, np.ndarray] = {}
        for prof in cand.profiles:
            X = [self.whitened(st, g, cache) for g in prof.groups]
            blocks = []
            for Xg in X:
                nrm = np.linalg.norm(Xg, axis=0)
                Z = Xg / np.where(nrm > 1e-300, nrm, 1.0)
                blocks.append(Z - Q @ (Q.T @ Z))
            absorbed = _absorption(X, Qgeo)
            absorbed_min = min(absorbed_min, absorbed)
            chosen, dbic, drss, rank, U = _greedy(blocks, y, rss0, self.n, self.lnn, cand.scan,
                                                  margin=self.opt.group_bic_margin)
            if not chosen:                       # report the whole candidate (ΔBIC > 0: not supported)
                chosen = list(range(len(blocks)))
                U = _orth(np.concatenate(blocks, axis=1), 1e-3)
                rank = U.shape[1]
                drss = float(np.sum((U.T @ y) ** 2))
                dbic = self.n * math.log(max(rss0 - drss, 1e-300) / rss0) + (rank + cand.scan) * self.lnn
            if dbic < best.delta_bic or best.profile is None:
                best = _Score(cand, prof, tuple(prof.groups[i] for i in chosen), dbic, drss, rank, U=U)
                best.absorbed = absorbed
        best.absorbed_min = absorbed_min
        if best.rank > 0:
            dof = self.n - Q.shape[1] - best.rank
            best.f_stat = (best.delta_rss / best.rank) / max((rss0 - best.delta_rss) / max(dof, 1), 1e-300)
            best.p_value = float(stats.f.sf(best.f_stat, best.rank, max(dof, 1)))
            Xs = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows)
                                 for g in best.groups], axis=1)
            best.gamma = _lstsq_scaled(Xs - Q @ (Q.T @ Xs), y, rcond=1e-6)
        else:
            best.delta_bic, best.groups = 0.0, ()
        return best

    def whitened(self, st: _State, g: Group, cache: dict) -> np.ndarray:
        """Whitened calibration-row regressor (3m, k) of a group; a profile-scaled group reuses its base's."""
        if g.base is None:
            return self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows)
        key = id(g.base)
        if key not in cache:
            cache[key] = self.eng.wflat(self.eng.regressor(st.J, st.kin, g.base), self.rows)
        return cache[key] * np.repeat(g.u[self.rows], 3)[:, None]

    def cross_validate(self, st: _State, sc: _Score) -> dict:
        """Blocked K-fold CV of the linear model with and without the candidate's selected groups."""
        by_time = sc.cand.time_effect and self.inp.t_s is not None
        folds = self.eng.folds(by_time, self.inp.t_s, self.opt.cv_folds, self.opt.seed)
        A0 = self.eng.design(st, self.rows)
        A1 = self.eng.design(st, self.rows, sc.groups)
        y = self.eng.wflat(self.eng.resid(st), self.rows)
        e0, e1 = self.eng.cv_errors(A0, y, folds), self.eng.cv_errors(A1, y, folds)
        d = np.sum(e0**2, axis=1) - np.sum(e1**2, axis=1)
        t = float(np.mean(d) / max(np.std(d, ddof=1) / math.sqrt(len(d)), 1e-300))
        b, a = _rms(self.eng.to_mm(e0, self.rows)), _rms(self.eng.to_mm(e1, self.rows))
        floor = self.inp.noise_floor_mm * math.sqrt(1.0 + 1.25 * A1.shape[1] / len(y))
        excess = max(b**2 - floor**2, 0.25 * b**2)
        frac = (b**2 - a**2) / excess
        return {"cv_rms_before_mm": b, "cv_rms_after_mm": a, "cv_gain_t": t, "excess_explained": frac,
                "cv_blocking": "time" if by_time else "pose", "cv_folds": len(folds),
                "ok": bool(np.mean(d) > 0 and t >= self.opt.cv_min_t and frac >= self.opt.min_excess_fraction)}

    def plausibility(self, st: _State, sc: _Score) -> tuple[bool, str]:
        if sc.cand.name in ("joint_compliance", "payload_deflection") and "torque_nm" in sc.cand.info:
            return self._physical_compliance(sc)
        at, problems = 0, []
        for g in sc.groups:
            th = sc.gamma[at:at + g.k]
            at += g.k
            lim = np.broadcast_to(np.asarray(g.limit, float), (g.k,))
            for name, v, L in zip(g.names, th, lim):
                if abs(v) > L:
                    problems.append(f"|{name}| = {abs(v):.3g} > {L:.3g}")
            if g.dq is not None:
                dq = np.abs(g.dq[self.rows] @ th).max()
                if dq > g.dq_limit:
                    problems.append(f"implied joint deflection {np.degrees(dq) * 60:.1f} arcmin > "
                                    f"{np.degrees(g.dq_limit) * 60:.1f} arcmin")
        return (not problems, "; ".join(problems) if problems else "within physical bounds")


    def _physical_compliance(self, sc: _Score) -> tuple[bool, str]:
        """Judge compliance on physical parameters: the fitted deflection of each joint (whatever groups carry it)
        regressed on the physical gravity torque gives the compliance c (rad/N*m) and stiffness k = 1/c; k must be
        at least the size-derived floor. Coefficients of a general basis are never judged on their own."""
        rows = self.rows
        tau = sc.cand.info["torque_nm"]
        k_min = sc.cand.info["stiffness_min_nm_per_rad"]
        dq = np.zeros((len(rows), self.inp.q_rad.shape[1]))
        at = 0
        for g in sc.groups:
            dq += g.dq[rows] @ sc.gamma[at:at + g.k]
            at += g.k
        problems, values = [], {}
        for j in sorted({j for g in sc.groups for j in g.joints}):
            t = tau[rows, j - 1]
            A = np.column_stack([t, np.ones(len(t))])
            c = float(np.linalg.lstsq(A, dq[:, j - 1], rcond=None)[0][0])
            k = 1.0 / c if abs(c) > 1e-300 else np.inf
            defl = abs(c) * float(np.ptp(t))
            values[j] = (k, defl)
            if abs(k) < k_min:
                problems.append(f"J{j} stiffness {abs(k):.3g} N*m/rad < {k_min:.3g} (size floor)")
        sc.physical = {f"J{j}": {"stiffness_nm_per_rad": k, "deflection_range_arcmin": np.degrees(d) * 60.0}
                       for j, (k, d) in values.items()}
        desc = "; ".join(f"J{j} k = {k:.3g} N*m/rad ({np.degrees(d) * 60:.2f}' over the data)"
                         for j, (k, d) in values.items())
        neg = [j for j, (k, _) in values.items() if k < 0]
        if neg:
            desc += f"; negative on J{', J'.join(map(str, neg))} (balancer over-compensation or another effect)"
        return (not problems, "; ".join(problems) if problems else desc)

    def split_consistency(self, st: _State, sc: _Score, exclude=None) -> dict:
        """Effect-agnostic stability check: fit geometry + the candidate on the near and the far half of the poses
        (horizontal reach below / above its median) and compare the candidate's parameters (Wald χ², k dof). A
        physical effect has one set of parameters; a proxy for structure along the reach does not."""
        rows = self.rows
        T = st.kin.T_tracker_base
        pb = (st.pred[rows] - T[:3, 3]) @ T[:3, :3]
        reach = np.hypot(pb[:, 0], pb[:, 1])
        A0 = self.eng.design(st, rows)
        y = self.eng.wflat(self.eng.resid(st), rows)
        if exclude is not None:                  # sc is in the model: take its columns out, add its part back
            cols, th = exclude
            y = y + A0[:, cols] @ th
            keep = np.ones(A0.shape[1], bool)
            keep[cols] = False
            A0 = A0[:, keep]
        X = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), rows) for g in sc.groups], axis=1)
        k = X.shape[1]
        est = []
        for half in (reach < np.median(reach), reach >= np.median(reach)):
            r3 = np.repeat(half, 3)
            M = np.concatenate([A0[r3], X[r3]], axis=1)
            nrm = np.linalg.norm(M, axis=0)
            nrm[nrm < 1e-300] = 1.0
            Ms = M / nrm
            beta = np.linalg.lstsq(Ms, y[r3], rcond=1e-10)[0]
            res = y[r3] - Ms @ beta
            s2 = float(res @ res) / max(int(r3.sum()) - M.shape[1], 1)
            C = s2 * np.linalg.pinv(Ms.T @ Ms)
            est.append(((beta / nrm)[-k:], (C / np.outer(nrm, nrm))[-k:, -k:]))
        d = est[0][0] - est[1][0]
        W = float(d @ np.linalg.pinv(est[0][1] + est[1][1]) @ d)
        Q0 = _orth(A0)
        Xv = X - Q0 @ (Q0.T @ X)                                        # the visible part of the effect
        full = _lstsq_scaled(np.concatenate([A0, X], axis=1), y)[-k:]
        ratio = float(np.linalg.norm(Xv @ d) / max(np.linalg.norm(Xv @ full), 1e-300))
        return {"chi2": W, "dof": k, "p_value": float(stats.chi2.sf(W, k)), "difference_ratio": ratio}

    def given(self, st: _State, sc: _Score, other_groups, Q, y) -> float:
        """ΔBIC of sc's groups once ``other_groups`` are in the model (both orthogonalised against Q)."""
        X = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows) for g in other_groups],
                           axis=1)
        P = _orth(X - Q @ (Q.T @ X), 1e-3)
        Z = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows) for g in sc.groups], axis=1)
        Z = Z - Q @ (Q.T @ Z)
        Z = Z - P @ (P.T @ Z)
        U = _orth(Z, 1e-3)
        y2 = y - P @ (P.T @ y)
        rss0 = float(y2 @ y2)
        d = float(np.sum((U.T @ y2) ** 2))
        return self.n * math.log(max(rss0 - d, 1e-300) / rss0) + U.shape[1] * self.lnn

    def half_widths(self, st: _State, sc: _Score) -> dict:
        """Approach-direction offset (half-width, arcmin) of each joint's residual by size of the last move:
        constant for backlash (it saturates), growing with the move for a read-back lag."""
        rows = self.rows
        move = self.inp.meta()["move"][rows]
        appr = self.inp.approach
        if appr is None:
            return {}
        r = self.eng.resid(st)[rows]
        Jq = st.J[rows][:, :, self.eng.joint_cols]
        out = {}
        edges = (0.0, 10.0, 30.0, 60.0, 100.0, np.inf)
        for j in sorted({j for g in sc.groups for j in g.joints}):
            jq = Jq[:, :, j - 1]
            x = np.einsum("ni,ni->n", r, jq) / np.maximum(np.einsum("ni,ni->n", jq, jq), 1e-12)   # rad
            s, m = np.asarray(appr)[rows, j - 1], np.degrees(np.abs(move[:, j - 1]))
            bins = {}
            for lo, hi in zip(edges[:-1], edges[1:]):
                b = (m >= lo) & (m < hi)
                if np.sum(b & (s > 0)) >= 5 and np.sum(b & (s < 0)) >= 5:
                    hw = 0.5 * (np.mean(x[b & (s > 0)]) - np.mean(x[b & (s < 0)]))
                    bins[f"{lo:.0f}-{hi:.0f} deg" if np.isfinite(hi) else f">{lo:.0f} deg"] = np.degrees(hw) * 60.0
            out[f"J{j}"] = bins
        return out


SEPARATING_EXPERIMENT = {
    frozenset({"joint_compliance", "gear_cyclic"}): "compare poses with equal q2 and different q3 (a J2 harmonic "
    "cannot depend on q3, gravity compliance does), or measure with a second payload",
    frozenset({"payload_deflection", "gear_cyclic"}): "measure the same poses with and without the payload",
    frozenset({"backlash", "readback_lag"}): "log the commanded joints (qc1..qcn), or approach the same poses with "
    "short and long moves from both sides",
    frozenset({"thermal_drift", "registration_drift"}): "re-measure floor reference nests during the run (tracker "
    "drift moves the nests, thermal growth does not)",
    frozenset({"joint_compliance", "payload_deflection"}): "measure with two payloads in alternating blocks",
    frozenset({"joint_compliance", "thermal_drift"}): "measure the poses in random order over the whole run",
}


def separating_experiment(a: str, b: str) -> str:
    return SEPARATING_EXPERIMENT.get(frozenset({a, b}),
                                     "widen the range of the inputs where they differ (joints, time, payload) "
                                     "or add a second SMR for orientation")


def _absorption(X, Qgeo) -> float:
    """1 - ||X_perp||^2 / ||X||^2 over unit-norm columns (effects.md §6 step 4)."""
    Z = np.concatenate(X, axis=1)
    nrm = np.linalg.norm(Z, axis=0)
    Z = Z[:, nrm > 1e-300] / nrm[nrm > 1e-300]
    if Z.shape[1] == 0:
        return 1.0
    Zp = Z - Qgeo @ (Qgeo.T @ Z)
    return float(1.0 - np.sum(Zp**2) / np.sum(Z**2))


def _overlap(U1, U2) -> float:
    """Cosine of the smallest principal angle between two orthonormal subspaces."""
    if U1 is None or U2 is None or U1.shape[1] == 0 or U2.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(U1.T @ U2, compute_uv=False)[0])


# ============================================================================ where
def _region_stats(r_b, w, floor_pt, idx):
    """(rms, floor, p) of residuals r_b (m, 3) mm / whitened w (m, 3) over indices idx."""
    k = len(idx)
    rms = float(np.sqrt(np.mean(np.sum(r_b[idx] ** 2, axis=1))))
    floor = float(np.sqrt(np.mean(floor_pt[idx] ** 2)))
    chi = float(np.sum(w[idx] ** 2))
    return rms, floor, float(stats.chi2.sf(chi, 3 * k))


def _edges(x, k):
    return np.quantile(x, np.linspace(0, 1, k + 1)[1:-1])


def _words_band(name, unit, lo, hi, labels, i, k):
    """'far reach (radius > 1300 mm)' style description of band i of k."""
    word = labels[i] if k == len(labels) else f"band {i + 1}/{k}"
    if i == 0:
        return f"{word} ({name} < {hi:.0f} {unit})"
    if i == k - 1:
        return f"{word} ({name} > {lo:.0f} {unit})"
    return f"{word} ({name} {lo:.0f}-{hi:.0f} {unit})"


def where_analysis(stage: str, r_mm: np.ndarray, cov_eff: np.ndarray, p_base: np.ndarray, q_rad: np.ndarray,
                   R_tracker_base: np.ndarray, t_s=None, approach=None, payload=None, Jq=None,
                   options: DiagnosisOptions = DiagnosisOptions()) -> tuple[list[Region], dict]:
    """Map residuals r_mm (m, 3, tracker frame) with their expected covariance cov_eff (m, 3, 3) over the
    workspace, joint ranges, base axes, time, approach direction and payload. Returns (flagged regions sorted by
    RMS/floor, full maps for plots)."""
    m = len(r_mm)
    R = np.asarray(R_tracker_base)[:3, :3]
    r_b = r_mm @ R                                    # base frame (R^T r)
    Lc = np.linalg.cholesky(cov_eff)
    w = np.linalg.solve(Lc, r_mm[:, :, None])[:, :, 0]
    floor_pt = np.sqrt(np.trace(cov_eff, axis1=1, axis2=2))
    cands: list[tuple[str, str, np.ndarray, dict]] = [("all evaluated points", "all", np.arange(m), {})]
    maps: dict = {}
    radius, z = np.hypot(p_base[:, 0], p_base[:, 1]), p_base[:, 2]
    er, ez = _edges(radius, 3), _edges(z, 3)
    br, bz = np.digitize(radius, er), np.digitize(z, ez)
    rl = ("near reach", "mid reach", "far reach")
    zl = ("low", "mid height", "high")
    bounds_r = np.concatenate([[radius.min()], er, [radius.max()]])
    bounds_z = np.concatenate([[z.min()], ez, [z.max()]])
    for i in range(3):
        cands.append((_words_band("radius", "mm", bounds_r[i], bounds_r[i + 1], rl, i, 3), "workspace",
                      np.flatnonzero(br == i), {}))
        cands.append((_words_band("z", "mm", bounds_z[i], bounds_z[i + 1], zl, i, 3), "workspace",
                      np.flatnonzero(bz == i), {}))
    for i in range(3):
        for k in range(3):
            idx = np.flatnonzero((br == i) & (bz == k))
            d1 = _words_band("radius", "mm", bounds_r[i], bounds_r[i + 1], rl, i, 3)
            d2 = _words_band("z", "mm", bounds_z[k], bounds_z[k + 1], zl, k, 3)
            desc = f"{rl[i]}, {zl[k]} ({d1.split('(')[1][:-1]}, {d2.split('(')[1][:-1]})"
            cands.append((desc, "workspace cell", idx, {}))
    maps["workspace"] = _grid_map(radius, z, r_b, floor_pt)
    qd = np.degrees(q_rad)
    maps["joints"] = []
    for j in range(q_rad.shape[1]):
        e = _edges(qd[:, j], 4)
        b = np.digitize(qd[:, j], e)
        lim = np.concatenate([[qd[:, j].min()], e, [qd[:, j].max()]])
        for i in range(4):
            cands.append((f"J{j + 1} in {lim[i]:.0f} to {lim[i + 1]:.0f} deg", "joint range", np.flatnonzero(b == i),
                          {"joint": j + 1}))
        maps["joints"].append(_line_map(qd[:, j], r_b, floor_pt, 8, f"J{j + 1} (deg)"))
    if t_s is not None and np.ptp(t_s) > 0:
        tm = (np.asarray(t_s) - np.min(t_s)) / 60.0
        e = _edges(tm, 6)
        b = np.digitize(tm, e)
        lim = np.concatenate([[tm.min()], e, [tm.max()]])
        for i in range(6):
            cands.append((f"t {lim[i]:.0f}-{lim[i + 1]:.0f} min", "time", np.flatnonzero(b == i), {}))
        maps["time"] = _line_map(tm, r_b, floor_pt, 12, "t (min)")
    if payload is not None:
        vals = np.unique(np.round(payload, 3))
        if len(vals) > 1:
            for v in vals:
                cands.append((f"payload {v:g} kg", "payload", np.flatnonzero(np.round(payload, 3) == v), {}))
    regions = []
    m_tests = len(cands) + 3 + (q_rad.shape[1] if approach is not None else 0)
    alpha = options.region_alpha / max(m_tests, 1)
    chi_all = float(np.sum(w**2))
    for desc, kind, idx, extra in cands:
        if len(idx) < 5:
            continue
        rms, floor, p = _region_stats(r_b, w, floor_pt, idx)
        rest = m - len(idx)
        if rest >= 5:
            chi = float(np.sum(w[idx] ** 2))
            F = (chi / (3 * len(idx))) / max((chi_all - chi) / (3 * rest), 1e-300)
            out = np.setdiff1d(np.arange(m), idx)
            extra = dict(extra, vs_rest_ratio=rms / max(float(np.sqrt(np.mean(np.sum(r_b[out] ** 2, axis=1)))), 1e-12),
                         stands_out=bool(stats.f.sf(F, 3 * len(idx), 3 * rest) < alpha))
        regions.append(Region(f"{desc}: RMS {rms:.3f} mm vs floor {floor:.3f} mm", rms, floor, len(idx), kind, stage,
                              p, dict(extra, region=desc)))
    # per base axis: RMS of one component vs its own floor
    cov_b = np.einsum("ji,njk,kl->nil", R, cov_eff, R)
    axes = []
    for a, name in enumerate(("x", "y", "z")):
        rms = float(np.sqrt(np.mean(r_b[:, a] ** 2)))
        fl = float(np.sqrt(np.mean(cov_b[:, a, a])))
        chi = float(np.sum(r_b[:, a] ** 2 / cov_b[:, a, a]))
        p = float(stats.chi2.sf(chi, m))
        label = f"base {name} axis" + (" (vertical)" if name == "z" else "")
        regions.append(Region(f"{label}: RMS {rms:.3f} mm vs floor {fl:.3f} mm", rms, fl, m, "axis", stage, p,
                              {"region": label}))
        axes.append({"axis": name, "rms_mm": rms, "floor_mm": fl})
    maps["axes"] = axes
    if approach is not None and Jq is not None:
        maps["approach"] = []
        for j in range(q_rad.shape[1]):
            reg = _approach_region(j, approach[:, j], r_mm, cov_eff, Jq[:, :, j], stage)
            if reg is not None:
                regions.append(reg)
                maps["approach"].append({"joint": j + 1, **reg.extra, "rms_mm": reg.rms_mm})
    flagged = [g for g in regions if g.p_value < alpha and (g.kind == "approach" or
                                                            g.rms_mm >= options.region_min_ratio * g.floor_mm)]
    flagged.sort(key=lambda g: (g.kind != "all", not (g.kind == "approach" or g.extra.get("stands_out", False)),
                                -g.rms_mm / max(g.floor_mm, 1e-12)))
    return flagged[:options.max_regions], maps


def _approach_region(j, s, r_mm, cov, jq, stage) -> Region | None:
    """Difference of the residual along joint j's motion between + and - approaches (Welch t)."""
    plus, minus = s > 0, s < 0
    if plus.sum() < 5 or minus.sum() < 5:
        return None
    u = jq / np.maximum(np.linalg.norm(jq, axis=1, keepdims=True), 1e-12)
    x = np.einsum("ni,ni->n", r_mm, u)
    var = np.einsum("ni,nij,nj->n", u, cov, u)
    res = stats.ttest_ind(x[plus], x[minus], equal_var=False)
    shift = float(np.mean(x[plus]) - np.mean(x[minus]))
    floor = float(np.sqrt(np.mean(var)))
    rms = float(np.sqrt(np.mean(x**2)))
    return Region(f"J{j + 1} approach direction: the residual along the J{j + 1} motion differs by {abs(shift):.3f} mm "
                  f"between + and - approaches (RMS {rms:.3f} mm vs floor {floor:.3f} mm)", rms, floor, len(s),
                  "approach", stage, float(res.pvalue), {"joint": j + 1, "shift_mm": shift, "t": float(res.statistic),
                                                         "region": f"J{j + 1} approach direction (+ vs -), shift "
                                                                   f"{shift:+.3f} mm"})


def _line_map(x, r_b, floor_pt, k, label):
    edges = np.linspace(np.min(x), np.max(x), k + 1)
    b = np.clip(np.digitize(x, edges[1:-1]), 0, k - 1)
    rms = [float(np.sqrt(np.mean(np.sum(r_b[b == i] ** 2, axis=1)))) if np.any(b == i) else None for i in range(k)]
    fl = [float(np.sqrt(np.mean(floor_pt[b == i] ** 2))) if np.any(b == i) else None for i in range(k)]
    return {"label": label, "edges": edges.tolist(), "rms_mm": rms, "floor_mm": fl,
            "n": [int(np.sum(b == i)) for i in range(k)]}


def _grid_map(radius, z, r_b, floor_pt, k=5):
    er, ez = np.linspace(radius.min(), radius.max(), k + 1), np.linspace(z.min(), z.max(), k + 1)
    br = np.clip(np.digitize(radius, er[1:-1]), 0, k - 1)
    bz = np.clip(np.digitize(z, ez[1:-1]), 0, k - 1)
    rms = [[None] * k for _ in range(k)]
    n = [[0] * k for _ in range(k)]
    for i in range(k):
        for j in range(k):
            sel = (br == i) & (bz == j)
            n[i][j] = int(sel.sum())
            if sel.any():
                rms[i][j] = float(np.sqrt(np.mean(np.sum(r_b[sel] ** 2, axis=1))))
    return {"radius_edges_mm": er.tolist(), "z_edges_mm": ez.tolist(), "rms_mm": rms, "n": n,
            "floor_mm": float(np.sqrt(np.mean(floor_pt**2)))}


# ============================================================================ structure left over
def structure_test(w: np.ndarray, spaces: Mapping[str, np.ndarray], rng: np.random.Generator, k: int = 10,
                   permutations: int = 200) -> dict:
    """Neighbour correlation of whitened residual vectors w (m, 3) in each feature space (m, d): statistic
    S = mean_i w_i . mean_{j in kNN(i)} w_j, z-score against residual permutations. Under pure noise S ~ 0;
    S estimates the structured variance in noise units (3 = as large as the noise)."""
    out = {}
    m = len(w)
    perms = np.stack([rng.permutation(m) for _ in range(permutations)])
    for name, F in spaces.items():
        F = np.asarray(F, float).reshape(m, -1)
        sd = F.std(axis=0)
        if np.all(sd <= 0) or m <= k + 1:
            continue
        F = F[:, sd > 0] / sd[sd > 0]
        F = F + 1e-9 * rng.standard_normal(F.shape)          # break ties (repeated values)
        _, nn = cKDTree(F).query(F, k=k + 1)
        nn = nn[:, 1:]
        A = sparse.csr_matrix((np.full(m * k, 1.0 / k), nn.ravel(), np.arange(0, m * k + 1, k)), shape=(m, m))
        S = float(np.mean(np.sum(w * (A @ w), axis=1)))
        Wp = np.concatenate([w[pp] for pp in perms], axis=1)            # (m, 3 x permutations)
        Sp = np.sum((Wp * (A @ Wp)).reshape(m, len(perms), 3), axis=(0, 2)) / m
        z = float((S - Sp.mean()) / max(Sp.std(ddof=1), 1e-12))
        out[name] = {"S": S, "z": z}
    return out


# ============================================================================ the diagnosis
def nest_drift(nests: NestReadings, floor_mm: float, alpha: float = 1e-3) -> dict | None:
    """Tracker drift seen by reference nests: each nest's readings (minus their mean) fitted with a quadratic in
    time (or in measurement order without timestamps); pooled F test against a constant; the drift is the largest
    3-D excursion of the fitted trends. ``ruled_out`` when not detected and its upper bound (trend + 3 standard
    errors) is below 1.5 x the noise floor (a drift range that adds less than 0.45 x the floor in RMS). None with fewer than 3 readings of any nest."""
    ids = np.asarray(nests.nest_id)
    x_all = np.asarray(nests.t_s if nests.t_s is not None else nests.order, float)
    span = float(np.ptp(x_all)) if len(x_all) else 0.0
    if span <= 0:
        return None
    rss0 = rss1 = 0.0
    dof1, k_extra, excursion, m_min = 0, 0, 0.0, np.inf
    slopes = []
    for nid in np.unique(ids):
        sel = ids == nid
        if sel.sum() < 4:
            continue
        x = (x_all[sel] - x_all.min()) / span
        p = np.asarray(nests.p_mm)[sel] - np.asarray(nests.p_mm)[sel].mean(axis=0)
        A = np.column_stack([np.ones(len(x)), x - x.mean(), (x - x.mean()) ** 2])
        beta, *_ = np.linalg.lstsq(A, p, rcond=None)
        trend = A[:, 1:] @ beta[1:]
        r = p - A @ beta
        rss0 += float(np.sum(p**2))
        rss1 += float(np.sum(r**2))
        dof1 += 3 * (len(x) - 3)
        k_extra += 6
        excursion = max(excursion, float(np.max(np.linalg.norm(trend - trend[:, None].mean(axis=0), axis=1))) * 2.0)
        m_min = min(m_min, len(x))
        xc = x - x.mean()
        slopes.append(xc @ p / max(float(xc @ xc), 1e-300))      # linear drift over the run (mm per run)
    if k_extra == 0 or dof1 <= 0:
        return None
    sigma = math.sqrt(rss1 / dof1)
    F = ((rss0 - rss1) / k_extra) / max(rss1 / dof1, 1e-300)
    p_value = float(stats.f.sf(F, k_extra, dof1))
    linear = float(np.linalg.norm(np.mean(slopes, axis=0)))        # common to all nests (the tracker moved)
    se = sigma * math.sqrt(12.0 / m_min) / math.sqrt(len(slopes))
    detected = p_value < alpha
    if not detected:
        excursion = linear
    bound = linear + 2.0 * math.sqrt(3.0) * se
    ruled_out = (not detected) and bound < 1.5 * floor_mm         # a range of 1.5 x floor is < 0.45 x floor RMS
    basis = "time" if nests.t_s is not None else "measurement order"
    summary = (f"nests moved {excursion:.3f} mm over the run (p = {p_value:.2g}, by {basis})" if detected else
               f"nests stable within {bound:.3f} mm (drift {excursion:.3f} mm, p = {p_value:.2g}, by {basis})")
    return {"detected": detected, "ruled_out": ruled_out, "drift_mm": excursion, "upper_bound_mm": bound,
            "p_value": p_value, "nest_sigma_mm": sigma, "n_nests": int(k_extra // 6), "basis": basis,
            "summary": summary}


def approach_from_order(q: np.ndarray) -> np.ndarray:
    """(N, n) sign of each joint's last motion from row order (rows in measurement order): the same rule as the
    interchange CSV (a joint that did not move keeps its previous sign; 0 before its first move)."""
    q = np.asarray(q, float)
    step = np.zeros_like(q)
    if len(q) > 1:
        step[1:] = np.sign(np.diff(q, axis=0))
    rows = np.where(step != 0.0, np.arange(len(q))[:, None], 0)
    last = np.maximum.accumulate(rows, axis=0)
    return step[last, np.arange(q.shape[1])[None, :]]


def repeat_dof(q: np.ndarray, decimals: int = 3) -> int:
    """Degrees of freedom (points) of ``repeat_floor``: sum over repeated poses of (count - 1)."""
    _, counts = np.unique(np.round(np.asarray(q, float), decimals), axis=0, return_counts=True)
    return int(np.sum(counts[counts >= 2] - 1))


def repeat_floor(q: np.ndarray, p_mm: np.ndarray, decimals: int = 3) -> float | None:
    """sqrt of the pooled within-pose variance of repeated poses (3-D, mm) or None without enough repeats
    (at least 2 poses and 6 degrees of freedom); the estimator of ``campaign.process.noise_floor_from_repeats``."""
    keys = np.round(np.asarray(q, float), decimals)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    groups = [np.flatnonzero(inverse.ravel() == g) for g in np.flatnonzero(counts >= 2)]
    dof = sum(len(g) - 1 for g in groups)
    if len(groups) < 2 or dof < 6:
        return None
    return float(np.sqrt(sum(np.sum((p_mm[g] - p_mm[g].mean(axis=0)) ** 2) for g in groups) / dof))


def _base_fit(inp: DiagnosisInput, opt: DiagnosisOptions):
    """Registration + identifiability + LM of the complete geometric model on the calibration rows."""
    cal = np.flatnonzero(inp.calib)
    res = calibrate(inp.kin, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], CalibrationOptions(method="lm"))
    layout = ParamLayout.of(res.kinematics)
    cols = np.array([layout.index(nm) for nm in res.identified], int)
    return res, cols


def diagnose(inp: DiagnosisInput, options: DiagnosisOptions = DiagnosisOptions()) -> Diagnosis:
    """Run the whole diagnosis on one dataset (see the module docstring)."""
    opt = options
    if inp.baseline is not None and inp.baseline_identified is not None:
        kin0 = inp.baseline
        layout = ParamLayout.of(kin0)
        cols = np.array([layout.index(nm) for nm in inp.baseline_identified], int)
    else:
        res, cols = _base_fit(inp, opt)
        kin0 = res.kinematics if inp.baseline is None else inp.baseline
    eng = _Engine(inp, cols, np.flatnonzero(inp.calib), np.flatnonzero(inp.test))
    if inp.baseline is not None:              # the best geometric model as given: "before" agrees everywhere
        pred, J = eng.predict(kin0, [], np.zeros(0))
        geo_state = _State(kin0, [], np.zeros(0), pred, J)
    st = eng.fit(kin0, [])
    outliers = _outliers(eng, st, opt)
    if len(outliers):
        eng.fit_rows = np.setdiff1d(eng.fit_rows, outliers)
        st = eng.fit(st.kin, [])
    if inp.baseline is None:
        geo_state = st
    drift = nest_drift(inp.nests, inp.noise_floor_mm) if inp.nests is not None else None
    meta = dict(inp.meta(), nest_drift=drift, order=np.arange(len(inp.q_rad)) if inp.order is None else inp.order)
    cands = build_candidates(st.kin, inp.q_rad, meta, eng.fit_rows, st.J, st.pred, opt)
    sel = _Selector(eng, inp, opt)
    Qgeo = _orth(eng.wflat(st.J[:, :, cols], eng.fit_rows))
    stages = [_stage_summary(eng, geo_state, [], opt)]
    if st is not geo_state:
        stages[0]["refit_test_rms_mm"] = eng.test_rms(st)
    st, accepted, last_scores = _forward(eng, sel, st, cands, stages, Qgeo, opt)
    st, accepted, stages, dropped = _backward(eng, sel, st, accepted, stages, opt)
    for _ in range(2):                  # what is left must pass again once the dropped effects are gone
        if not dropped or not accepted:
            break
        st, accepted, stages, more = _backward(eng, sel, st, accepted, stages, opt)
        if not more:
            break
        dropped += more
    return _assemble(inp, opt, eng, sel, cands, geo_state, st, accepted, stages, last_scores, dropped, outliers, Qgeo)


def _forward(eng, sel, st, cands, stages, Qgeo, opt):
    """Forward stepwise selection; appends one stage per step. Returns (state, accepted scores, last scores)."""
    accepted: list[_Score] = []
    pool = [c for c in cands if c.profiles and not c.reason]
    last_scores: dict[str, _Score] = {}
    while pool and len(accepted) < opt.max_effects:
        Q, y, _ = sel.base(st)
        scores = sorted((sel.score(c, st, Q, y, Qgeo) for c in pool), key=lambda s: s.delta_bic)
        last_scores = {s.cand.key: s for s in scores}
        chosen = _pick(sel, st, scores, opt, pool)
        if chosen is None:
            break
        new = eng.fit(st.kin, st.groups + list(chosen.groups), np.concatenate([st.theta, chosen.gamma]))
        _record(chosen, accepted, scores, len(stages), opt)
        st = new
        stages.append(dict(_stage_summary(eng, st, accepted, opt), added=_added_label(chosen)))
        pool = [c for c in pool if c.key != chosen.cand.key]
        rest = chosen.cand.rest(chosen.profile, chosen.groups)      # its other groups may enter later
        if rest is not None:
            pool.append(rest)
        twin = ELASTIC_TWIN.get(chosen.cand.name)
        other = next((c for c in pool if c.name == twin and not c.extends), None)
        if other is not None and not chosen.cand.extends:     # one gravity-elastic effect: the other refines it
            pool = [c for c in pool if c is not other]
            pool.append(Candidate(chosen.cand.name, chosen.cand.joints, other.profiles, notes=chosen.cand.notes,
                                  extends=True, info=other.info))
    return st, accepted, last_scores


ELASTIC_TWIN = {"joint_compliance": "payload_deflection", "payload_deflection": "joint_compliance"}
SATURATION_PARTNER = {"backlash": "readback_lag", "readback_lag": "backlash", "joint_compliance": "payload_deflection"}


def _pick(sel, st, scores, opt, pool=()) -> _Score | None:
    """The strongest evidence (lowest ΔBIC) that passes every named gate: absorption, veto (direct comparison),
    blocked CV, physical plausibility, saturation test (backlash vs read-back lag). A better-scored candidate that
    a gate rejected and whose visible subspace overlaps the winner's is kept with it as one confusable class."""
    rejected = []
    Q = y = None
    for sc in scores:
        if sc.delta_bic >= -opt.bic_threshold:
            return None
        if sc.absorbed_min > opt.absorbed_limit:
            sc.rejected = f"{100 * sc.absorbed_min:.0f} % absorbed by the geometric model"
            continue
        if sc.cand.veto:
            sc.rejected = sc.cand.veto
            rejected.append(sc)
            continue
        sc.cv = sel.cross_validate(st, sc)
        sc.plausible = sel.plausibility(st, sc)
        if not sc.cv["ok"]:
            sc.rejected = _cv_reason(sc.cv, opt)
        elif not sc.plausible[0]:
            sc.rejected = f"implausible values: {sc.plausible[1]}"
        else:
            partner = SATURATION_PARTNER.get(sc.cand.name)
            other = next((c for c in pool if c.name == partner and c.profiles and not c.reason and not c.veto
                          and not c.extends), None)
            if other is not None:
                if Q is None:
                    Q, y, _ = sel.base(st)
                js = {j for g in sc.groups for j in g.joints}
                og = [g for g in other.profiles[0].groups if set(g.joints) & js]
                if og:
                    dbic = sel.given(st, sc, og, Q, y)
                    elastic = sc.cand.name == "joint_compliance"
                    key = "nested_test" if elastic else "saturation_test"
                    sc.physical[key] = {"delta_bic_given_" + partner: dbic}
                    if not elastic:
                        sc.physical[key]["half_width_arcmin_by_move"] = sel.half_widths(st, sc)
                    if dbic >= -opt.bic_threshold:
                        sc.rejected = (
                            f"nested test: the arm's own weight adds ΔBIC {dbic:+.1f} beyond the payload torque "
                            "(payload deflection of a balanced arm)" if elastic else "saturation test: " + (
                                "the approach offset grows with the size of the move (read-back lag); backlash adds "
                                if sc.cand.name == "backlash" else
                                "the approach offset does not grow with the move (it saturates: backlash); the lag "
                                "adds ") + f"ΔBIC {dbic:+.1f} once {partner} is modelled")
                        rejected.append(sc)
                        continue
            sc.shadowed = [r for r in rejected if r.cand.name != sc.cand.name and _overlap(r.U, sc.U) > 0.5]
            return sc
        rejected.append(sc)
    return None


def _record(chosen: _Score, accepted: list, scores, step: int, opt) -> None:
    """Add the chosen score to the accepted list (or to its owner when it extends an accepted effect)."""
    if chosen.cand.extends:
        owner = next(s for s in accepted if s.cand.key == chosen.cand.key)
        owner.groups = tuple(owner.groups) + tuple(chosen.groups)
        owner.steps.append(step)
        owner.extensions.append({"step": step, "groups": [g.label for g in chosen.groups], "dof": chosen.rank,
                                 "delta_bic": chosen.delta_bic, **{k: v for k, v in chosen.cv.items() if k != "ok"}})
        return
    chosen.confusable = [_confusion_entry(chosen, o) for o in scores if o is not chosen
                         and o.delta_bic < -opt.bic_threshold and o.cand.name != chosen.cand.name
                         and o.delta_bic - chosen.delta_bic < opt.bic_threshold
                         and _overlap(chosen.U, o.U) > 0.5 and not any(o is r for r in chosen.shadowed)]
    chosen.confusable += [dict(_confusion_entry(chosen, o), rejected_by=o.rejected) for o in chosen.shadowed]
    chosen.steps.append(step)
    accepted.append(chosen)


def _cv_reason(cv: dict, opt: DiagnosisOptions) -> str:
    if cv["cv_gain_t"] < opt.cv_min_t:
        return f"cross-validated error does not fall significantly (t = {cv['cv_gain_t']:.1f})"
    return (f"removes only {100 * cv['excess_explained']:.1f} % of the cross-validated excess over the noise floor "
            f"(< {100 * opt.min_excess_fraction:.0f} %)")


def _outliers(eng: _Engine, st: _State, opt: DiagnosisOptions) -> np.ndarray:
    rows = eng.fit_rows
    w = _whiten(eng.W[rows], eng.resid(st)[rows])
    d = np.sqrt(np.sum(w**2, axis=1) / 3.0)
    s = 1.4826 * np.median(np.abs(w))
    bad = rows[d > opt.outlier_sigma * max(s, 1e-12)]
    return bad if len(bad) < 0.1 * len(rows) else np.array([], int)


def _added_label(sc: _Score) -> str:
    js = sorted({j for g in sc.groups for j in g.joints})
    label = sc.cand.name + (f" J{','.join(map(str, js))}" if js else "")
    return label + (" (more terms)" if sc.cand.extends else "")


def _stage_summary(eng, st, accepted, opt) -> dict:
    """Test RMS and pose-blocked CV RMS of the model with the accepted effects so far."""
    folds = eng.folds(False, None, opt.cv_folds, opt.seed)
    A = eng.design(st, eng.fit_rows)
    y = eng.wflat(eng.resid(st), eng.fit_rows)
    e = eng.cv_errors(A, y, folds)
    e_mm = eng.to_mm(e, eng.fit_rows)
    return {"added": "geometric model", "effects": [s.cand.key for s in accepted], "test_rms_mm": eng.test_rms(st),
            "cv_rms_mm": _rms(e_mm),
            "calib_rms_mm": _rms(eng.resid(st)[eng.fit_rows]), "n_params": A.shape[1], "_cv_w": e}


def _backward(eng, sel, st, accepted, stages, opt):
    """One backward pass: drop an accepted effect whose removal no longer costs ΔBIC < -threshold given the
    others (its fitted contribution, orthogonalised against everything else, is what removing it would cost)."""
    dropped = []
    if not accepted:
        return st, accepted, stages, dropped
    _, y, A = sel.base(st)
    rss = float(y @ y)
    proxies = []
    for sc in accepted:                 # effect-agnostic: one physical effect has one set of parameters
        split = sel.split_consistency(st, sc, _columns_of(eng, st, sc.groups))
        sc.physical["reach_split"] = split
        if split["p_value"] < opt.split_alpha and split["difference_ratio"] > opt.split_min_ratio:
            sc.split_rejected = (f"its parameters differ between near and far reach in the final model (Wald χ² "
                                 f"{split['chi2']:.0f}, p = {split['p_value']:.1g}; the two fits differ by "
                                 f"{100 * split['difference_ratio']:.0f} % of the effect): it stands in for "
                                 "structure along the reach")
            proxies.append(sc)
    for sc in accepted:
        if sc not in proxies and any(_overlap(p.U, sc.U) > 0.5 for p in proxies):
            p = next(p for p in proxies if _overlap(p.U, sc.U) > 0.5)
            sc.split_rejected = (f"it overlaps {p.cand.name}, which stands in for structure along the reach: the "
                                 "same structure, not an effect of the library")
            proxies.append(sc)
    dropped += proxies
    for sc in accepted:
        if sc in proxies:
            continue
        cols, th = _columns_of(eng, st, sc.groups)
        mask = np.ones(A.shape[1], bool)
        mask[cols] = False
        by_time = sc.cand.time_effect and sel.inp.t_s is not None
        folds = eng.folds(by_time, sel.inp.t_s, opt.cv_folds, opt.seed)
        yr = eng.wflat(eng.resid(st), eng.fit_rows) + A[:, cols] @ th     # the data as the model without it sees them
        e0, e1 = eng.cv_errors(A[:, mask], yr, folds), eng.cv_errors(A, yr, folds)
        dd = np.sum(e0**2, axis=1) - np.sum(e1**2, axis=1)
        sc.refit_cv_t = float(np.mean(dd) / max(np.std(dd, ddof=1) / math.sqrt(len(dd)), 1e-300))
        if sc.refit_cv_t < opt.cv_min_t:
            dropped.append(sc)
    for sc in (accepted if len(accepted) >= 2 else ()):
        if sc in dropped:
            continue
        cols, th = _columns_of(eng, st, sc.groups)
        mask = np.ones(A.shape[1], bool)
        mask[cols] = False
        Qo = _orth(A[:, mask])
        d = A[:, cols] @ th
        d = d - Qo @ (Qo.T @ d)
        Xp = A[:, cols] - Qo @ (Qo.T @ A[:, cols])
        r_k = _orth(Xp, 1e-3).shape[1] if np.any(Xp) else 0
        sc.backward_delta_bic = sel.n * math.log(rss / (rss + float(d @ d))) + r_k * sel.lnn
        if sc.backward_delta_bic > -opt.bic_threshold:
            dropped.append(sc)
    pruned = False
    for sc in accepted:                 # groups (joints, terms) that the final model no longer needs
        if sc in dropped or len(sc.groups) < 2:
            continue
        for g in list(sc.groups):
            if _removal_bic(sel, eng, st, A, rss, [g]) > -opt.group_bic_margin and len(sc.groups) > 1:
                sc.groups = tuple(h for h in sc.groups if h is not g)
                sc.pruned.append(g.label)
                pruned = True
    if not dropped and not pruned:
        return st, accepted, stages, dropped
    keep = [s for s in accepted if s not in dropped]
    stages = stages[:1]
    kin = st.kin
    for i, s in enumerate(keep):
        st = eng.fit(kin, [g for s in keep[:i + 1] for g in s.groups])
        s.steps = [i + 1]
        stages.append(dict(_stage_summary(eng, st, keep[:i + 1], opt), added=_added_label(s)))
    if not keep:
        st = eng.fit(kin, [])
    return st, keep, stages, dropped


def _removal_bic(sel, eng, st, A, rss, groups) -> float:
    """ΔBIC of keeping ``groups`` in the final linearised model (negative: they are needed)."""
    cols, th = _columns_of(eng, st, groups)
    mask = np.ones(A.shape[1], bool)
    mask[cols] = False
    Qo = _orth(A[:, mask])
    d = A[:, cols] @ th
    d = d - Qo @ (Qo.T @ d)
    Xp = A[:, cols] - Qo @ (Qo.T @ A[:, cols])
    r_k = _orth(Xp, 1e-3).shape[1] if np.any(Xp) else 0
    return sel.n * math.log(rss / (rss + float(d @ d))) + r_k * sel.lnn


def _confusion_entry(best: _Score, other: _Score) -> dict:
    return {"effect": other.cand.name, "joints": list(other.joints), "delta_bic": other.delta_bic,
            "log10_bayes_factor": (other.delta_bic - best.delta_bic) / (2.0 * math.log(10.0)),
            "overlap": _overlap(best.U, other.U),
            "experiment": separating_experiment(best.cand.name, other.cand.name)}


def _params(sc: _Score, theta: np.ndarray | None = None) -> dict:
    vals = sc.gamma if theta is None else theta
    names = [f"{g.label}:{nm}" if g.label not in nm else nm for g in sc.groups for nm in g.names]
    return dict(zip(names, (float(v) for v in vals)))


def _columns_of(eng, st, groups):
    """Design-column indices (after the geometric ones) and fitted parameters of ``groups`` in state ``st``."""
    cols, th, at = [], [], len(eng.cols)
    ti = 0
    for g in st.groups:
        if any(g is h for h in groups):
            cols += list(range(at, at + g.k))
            th.append(st.theta[ti:ti + g.k])
        at += g.k
        ti += g.k
    return np.array(cols, int), (np.concatenate(th) if th else np.zeros(0))


def _assemble(inp, opt, eng, sel, cands, geo_state, st, accepted, stages, last_scores, dropped,
              outliers, Qgeo) -> Diagnosis:
    evaluation = "test" if len(eng.test_rows) else "cv"
    key = "test_rms_mm" if evaluation == "test" else "cv_rms_mm"
    findings = _accepted_findings(eng, st, accepted, stages, key, inp.noise_floor_mm)
    final = stages[-1][key]
    for sc in dropped:
        ev = _evidence(sc, inp.noise_floor_mm, final)
        ev["reason"] = (sc.split_rejected if sc.split_rejected else
                        f"does not survive the refit with the other accepted effects (cross-validated t "
                        f"{sc.refit_cv_t:.1f} < {opt.cv_min_t:g})" if sc.refit_cv_t < opt.cv_min_t else
                        f"dropped in the backward step (ΔBIC of keeping it {sc.backward_delta_bic:.1f})")
        findings.append(Finding(sc.cand.name, sc.joints, False, final, final, ev))
    done = {s.cand.key for s in accepted} | {s.cand.key for s in dropped}
    others, undiagnosable = _other_findings(eng, sel, st, [c for c in cands if c.key not in done], last_scores,
                                            final, inp.noise_floor_mm, Qgeo, opt)
    where, maps = _where_stages(inp, opt, eng, geo_state, st, stages)
    structure, unexplained, notes = _leftover(inp, opt, eng, st, stages, inp.noise_floor_mm)
    drift = next((c.info["nest_drift"] for c in cands if c.name == "registration_drift" and c.info.get("nest_drift")),
                 None)
    if drift:
        notes.append(("tracker drift ruled out by the reference nests: " if drift["ruled_out"] else
                      "reference nests: tracker drift detected, " if drift["detected"] else
                      "reference nests: drift neither detected nor ruled out, ") + drift["summary"])
    final_regions = maps.pop("_final_regions")
    if unexplained:
        where += [r for r in final_regions if r.kind != "all"]
    for s in stages:
        s.pop("_cv_w", None)
    return Diagnosis(float(inp.noise_floor_mm), inp.noise_floor_source, stages[0][key], final, unexplained,
                     tuple(findings + others), tuple(where), tuple(undiagnosable), evaluation, structure, maps,
                     tuple(notes), len(eng.fit_rows), len(eng.test_rows), tuple(int(i) for i in outliers), st.kin,
                     tuple(zip(st.groups, _split_theta(st))), tuple(stages))


def _accepted_findings(eng, st, accepted, stages, key, floor) -> list[Finding]:
    """One finding per accepted effect: RMS before its first step and after its last, shrinkage predicted by
    calibration CV vs achieved on the test rows, parameters of the final nonlinear fit."""
    findings = []
    for sc in accepted:
        first, last = sc.steps[0], sc.steps[-1]
        before, after = stages[first - 1][key], stages[last][key]
        ev = _evidence(sc, floor, after)
        predicted = sc.cv["cv_rms_before_mm"] - sc.cv["cv_rms_after_mm"]
        predicted += sum(e["cv_rms_before_mm"] - e["cv_rms_after_mm"] for e in sc.extensions)
        achieved = sum(stages[s - 1][key] - stages[s][key] for s in sc.steps)
        ev.update(step=first, parameters=_params(sc, _columns_of(eng, st, sc.groups)[1]),
                  predicted_shrinkage_mm=predicted, achieved_shrinkage_mm=achieved)
        if sc.cand.name == "readback_lag":
            ev["lag_deg_per_deg"] = _lags(ev["parameters"])
        ev.update(_physical_values(sc.cand.name, ev["parameters"]))
        if sc.pruned:
            ev["pruned_groups"] = list(sc.pruned)
        if sc.extensions:
            ev["extended"] = sc.extensions
            ev["dof"] = sc.rank + sum(e["dof"] for e in sc.extensions)
        if sc.cand.notes:
            ev["notes"] = list(sc.cand.notes)
        findings.append(Finding(sc.cand.name, sc.joints, True, before, after, ev))
    return findings


def _other_findings(eng, sel, st, cands, last_scores, final, floor, Qgeo, opt):
    """The candidates not accepted: why not, and what adding them now would do (linearised, on the test rows);
    plus the list of what these data cannot reveal, with the experiment that would."""
    Q, y, _ = sel.base(st)
    rest, undiagnosable = [], []
    for c in cands:
        if c.veto and not c.profiles:
            ev = {"diagnosable": True, "reason": c.veto}
            ev.update({k: v for k, v in c.info.items() if k != "torque_nm"})
            rest.append((np.inf, Finding(c.name, c.joints, False, final, final, ev)))
            continue
        if c.reason or not c.profiles:
            undiagnosable.append({"effect": c.name, "joints": list(c.joints), "reason": c.reason,
                                  "remedy": REMEDY[c.name]})
            ev = {"diagnosable": False, "reason": c.reason, "remedy": REMEDY[c.name]}
            if c.info.get("nest_drift"):
                ev["nest_drift"] = c.info["nest_drift"]
            rest.append((np.inf, Finding(c.name, c.joints, False, final, final, ev)))
            continue
        sc = sel.score(c, st, Q, y, Qgeo)
        prev = last_scores.get(c.key)
        ev = _evidence(sc, floor, final)
        if sc.rank == 0:
            ev["reason"] = "no part of it is visible beyond the current model"
        elif sc.absorbed_min > opt.absorbed_limit:
            ev["diagnosable"] = False
            ev["reason"] = f"{100 * sc.absorbed_min:.0f} % absorbed by the geometric model"
            undiagnosable.append({"effect": c.name, "joints": list(c.joints), "reason": ev["reason"],
                                  "remedy": REMEDY[c.name]})
        elif sc.delta_bic >= -opt.bic_threshold:
            ev["reason"] = f"not supported by the data (ΔBIC {sc.delta_bic:.1f} >= -{opt.bic_threshold:g})"
        else:
            sc.cv = sel.cross_validate(st, sc)
            sc.plausible = sel.plausibility(st, sc)
            ev = _evidence(sc, floor, final)
            ev["reason"] = (c.veto if c.veto else prev.rejected if prev is not None and prev.rejected else
                            _cv_reason(sc.cv, opt) if not sc.cv["ok"] else
                            f"implausible values: {sc.plausible[1]}" if not sc.plausible[0] else
                            f"limit of {opt.max_effects} effects reached")
        if c.veto:
            ev["reason"] = c.veto
        if c.notes:
            ev["notes"] = list(c.notes)
        after = _what_if(eng, st, sc) if sc.rank else final
        rest.append((sc.delta_bic, Finding(c.name, sc.joints, False, final, after, ev)))
    return [f for _, f in sorted(rest, key=lambda x: x[0])], undiagnosable


def _split_theta(st):
    out, at = [], 0
    for g in st.groups:
        out.append(st.theta[at:at + g.k])
        at += g.k
    return out


def _evidence(sc: _Score, floor: float, after: float) -> dict:
    ev = {"diagnosable": True, "delta_bic": sc.delta_bic, "f_statistic": sc.f_stat, "p_value": sc.p_value,
          "dof": sc.rank, "absorbed_fraction": sc.absorbed,
          "profile": sc.profile.label if sc.profile else None, "groups": [g.label for g in sc.groups],
          "remaining_vs_floor": after / floor if floor > 0 else None}
    if sc.cv:
        ev.update({k: v for k, v in sc.cv.items() if k != "ok"})
    if sc.plausible:
        ev["plausible"], ev["plausibility"] = sc.plausible
    if sc.gamma is not None and "parameters" not in ev:
        ev["parameters"] = _params(sc)
    conf = sc.confusable
    if conf:
        ev["confusable_with"] = conf
        ev["class"] = " / ".join([sc.cand.name] + [c["effect"] for c in conf])
        ev["experiment"] = "; ".join(dict.fromkeys(c["experiment"] for c in conf))
    if sc.cand.name == "joint_compliance":
        ev["elastic_class"] = ELASTIC_CLASS
        ev.setdefault("class", ELASTIC_CLASS)
    if sc.physical:
        ev["physical"] = sc.physical
    if sc.cand.info.get("nest_drift"):
        ev["nest_drift"] = sc.cand.info["nest_drift"]
    if "direct_comparison" in sc.cand.info:
        ev["direct_comparison"] = {f"J{j}": v for j, v in sc.cand.info["direct_comparison"].items()}
    if sc.cand.name == "readback_lag" and sc.gamma is not None:
        ev["lag_deg_per_deg"] = _lags(_params(sc))
    if np.isfinite(sc.refit_cv_t):
        ev["refit_cv_t"] = sc.refit_cv_t
    return ev


def _physical_values(name: str, params: dict) -> dict:
    """Physical reading of fitted parameters: gear amplitude per harmonic (arcsec), backlash half-width (arcmin)."""
    if name == "gear_cyclic":
        amp = {}
        for k, v in params.items():
            h = k.split(":")[-1]
            if h.startswith("sin"):
                c = params.get(k.replace("sin", "cos"), 0.0)
                amp[f"h{h[3:]}"] = math.degrees(math.hypot(v, c)) * 3600.0
        return {"amplitude_arcsec": amp}
    if name == "backlash":
        return {"half_width_arcmin": {k.split(":")[-1].replace("b", "J"): math.degrees(abs(v)) * 60.0 / 2.0
                                      for k, v in params.items()}}
    return {}


def _lags(params: dict) -> dict:
    """Read-back lag per joint (deg/deg) from the fitted parameters (-lambda)."""
    return {k.split(":")[-1].replace("lag", "J"): -v for k, v in params.items() if k.split(":")[-1].startswith("lag")}


def _what_if(eng: _Engine, st: _State, sc: _Score) -> float:
    """Test (or CV) RMS if the candidate's selected groups were added, from the linearised joint fit."""
    rows = eng.fit_rows
    A1 = eng.design(st, rows, sc.groups)
    y = eng.wflat(eng.resid(st), rows)
    beta = _lstsq_scaled(A1, y)
    if len(eng.test_rows) == 0:
        e = eng.cv_errors(A1, y, eng.folds(False, None, 5, 0))
        return _rms(eng.to_mm(e, rows))
    T = eng.test_rows
    parts = [st.J[T][:, :, eng.cols]] + [eng.regressor(st.J, st.kin, g)[T] for g in list(st.groups) + list(sc.groups)]
    At = np.concatenate(parts, axis=2)
    r = eng.resid(st)[T] - At @ beta
    return _rms(r)


def _eval_set(eng: _Engine, st: _State, cv_w: np.ndarray):
    """Held-out residuals (mm): CV on the calibration rows + test rows; their row indices."""
    cv_mm = eng.to_mm(cv_w, eng.fit_rows)
    rows = np.concatenate([eng.fit_rows, eng.test_rows])
    r = np.concatenate([cv_mm, eng.resid(st)[eng.test_rows]]) if len(eng.test_rows) else cv_mm
    return r, rows


def _where_stages(inp, opt, eng, geo_state, st, stages):
    out_regions, maps = [], {}
    for name, state, stage in (("geometric", geo_state, stages[0]), ("final", st, stages[-1])):
        r, rows = _eval_set(eng, state, stage["_cv_w"])
        inflate = 1.0 + 1.25 * stage["n_params"] / (3.0 * len(eng.fit_rows))    # parameter error, 4/5 folds
        cov = inp.cov_mm2[rows] * _floor_scale(inp) * inflate
        T = state.kin.T_tracker_base
        p_base = (state.pred[rows] - T[:3, 3]) @ T[:3, :3]
        Jq = state.J[rows][:, :, eng.joint_cols]
        regs, mp = where_analysis(name, r, cov, p_base, inp.q_rad[rows], T,
                                  None if inp.t_s is None else np.asarray(inp.t_s)[rows],
                                  None if inp.approach is None else np.asarray(inp.approach)[rows],
                                  None if inp.payload_kg is None else np.asarray(inp.payload_kg)[rows], Jq, opt)
        maps[name] = mp
        if name == "geometric":
            out_regions += regs
        else:
            maps["_final_regions"] = regs
    return out_regions, maps


def _floor_scale(inp: DiagnosisInput) -> float:
    """Factor on the covariance so that its RMS equals the reported noise floor."""
    spec = math.sqrt(float(np.mean(np.trace(inp.cov_mm2, axis1=1, axis2=2))))
    return (inp.noise_floor_mm / spec) ** 2 if spec > 0 and inp.noise_floor_mm > 0 else 1.0


def _leftover(inp, opt, eng, st, stages, floor):
    """Structure test on the final in-sample calibration residuals; unexplained flag and notes."""
    rows = eng.fit_rows
    p_eff = stages[-1]["n_params"]
    cov = inp.cov_mm2[rows] * _floor_scale(inp)
    r = eng.resid(st)[rows]
    w = np.linalg.solve(np.linalg.cholesky(cov), r[:, :, None])[:, :, 0]
    dof = 3 * len(rows) - p_eff
    chi2 = float(np.sum(w**2) / max(dof, 1))
    T = st.kin.T_tracker_base
    p_base = (st.pred[rows] - T[:3, 3]) @ T[:3, :3]
    q = inp.q_rad[rows]
    spaces = {"joint space": q, "workspace": p_base, "reach": np.hypot(p_base[:, 0], p_base[:, 1]),
              "height": p_base[:, 2]}
    for j in range(q.shape[1]):
        spaces[f"J{j + 1}"] = q[:, j]
    if inp.t_s is not None and np.ptp(np.asarray(inp.t_s)[rows]) > 0:
        spaces["time"] = np.asarray(inp.t_s)[rows]
    tests = structure_test(w, spaces, np.random.default_rng(opt.seed), opt.neighbours, opt.permutations)
    z_thr = opt.structure_z
    best = max(tests, key=lambda s: tests[s]["z"]) if tests else None
    s_val = tests[best]["S"] if best else 0.0
    structured_rms = floor * math.sqrt(max(s_val, 0.0) / 3.0)
    structured = bool(best and tests[best]["z"] >= z_thr and structured_rms >= opt.structure_min_fraction * floor)
    along = sorted((n for n in tests if tests[n]["z"] >= z_thr), key=lambda n: -tests[n]["z"])
    notes = []
    if inp.noise_floor_dof:          # the floor is an estimate itself: F test of the two variances
        chi_limit = float(stats.f.isf(0.001, max(dof, 1), 3 * inp.noise_floor_dof))
    else:
        chi_limit = 1.0 + 3.0 * math.sqrt(2.0 / max(dof, 1))
    excess = stages[-1]["cv_rms_mm"] > 1.12 * floor * math.sqrt(1.0 + 1.25 * p_eff / (3.0 * len(rows)))
    scatter = bool(chi2 > chi_limit and excess and not structured)
    unexplained = structured or scatter
    if scatter:
        why = ("unlogged approach-direction dependence, a drift without timestamps, aliased high-frequency gear "
               "error" + (", or a noise model that is too optimistic" if inp.noise_floor_source == "specs" else ""))
        notes.append(f"unexplained residual scatter {math.sqrt(chi2):.2f}x the noise floor without spatial "
                     f"structure: {why}")
    structure = {"chi2_per_dof": chi2, "chi2_limit": chi_limit, "structured": structured, "scatter": scatter,
                 "structured_rms_mm": structured_rms,
                 "strongest_space": best, "structure_along": along,
                 "tests": {k: {"S": v["S"], "z": v["z"]} for k, v in tests.items()},
                 "excess_rms_mm": math.sqrt(max(stages[-1]["cv_rms_mm"] ** 2 - floor**2, 0.0))}
    final_cv = stages[-1]["cv_rms_mm"]
    if scatter and len(stages) > 1:
        share = (stages[0]["cv_rms_mm"] ** 2 - final_cv**2) / max(stages[0]["cv_rms_mm"] ** 2 - floor**2, 1e-300)
        if share < 0.5:
            notes.append(f"the accepted effects remove only {100 * share:.0f} % of the excess over the floor and the rest "
                         "is unstructured scatter: treat the attribution as partial")
    if inp.noise_floor_source == "repeats" and final_cv < 0.8 * floor:
        notes.append(f"the repeat scatter ({floor:.3f} mm) exceeds the final cross-validated residual "
                     f"({final_cv:.3f} mm): the repeated poses probably include approach-direction or drift effects, "
                     "so the floor is overestimated")
    if structured:
        notes.append(f"unexplained structured residual of about {structured_rms:.3f} mm RMS, strongest along "
                     f"{', '.join(along[:4])}")
    return structure, unexplained, notes
