"""The campaign configuration schema: frozen dataclasses (one per YAML section) and the value tables.

Read by :mod:`campaign.config.load`, which re-exports every name here."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from campaign.errors import ConfigError
from campaign.config.bounded_yaml import load_limited, read_limited

from drivers.registry import ROBOT_SCHEMES, TRACKER_SCHEMES  # noqa: E402  (the registry owns the url schemes)
from robocal.effects import MODEL_EFFECTS as MODEL_EFFECT_NAMES  # noqa: E402  (robocal owns the effect names)
CONVENTIONS = ("dh", "mdh")
CALIBRATION_METHODS = ("robust_ridge", "lm")
WEIGHT_FUNCTIONS = ("igg3", "huber", "none")
RESIDUAL_MODELS = ("idw", "gpr", "none", "auto")
OUTLIER_SCREENS = ("local", "none")
JOINT_SETS = ("auto", "commanded", "readback")
PLAN_ORDERS = ("serpentine", "random")
PLAN_KINDS = ("grid", "optimal", "iso9283")
STOP_RULES = ("off", "auto")
CORRECTION_GENERATORS = ("ensemble", "yin", "fixed", "add", "multiply", "euler_zyz", "euler_xyz", "quaternion")
ERROR_FUNCTIONS = ("position", "pose")
from robocal.effects import SIMULATED_EFFECTS as EFFECT_NAMES  # noqa: E402  (one owner: robocal.effects)
# tracker.uncertainty: robocal owns the class and its numerics; the YAML section requires the four MPE terms
# (micrometres, micrometres per metre) and takes coverage_k (default 2), see campaign.config.load._uncertainty
from robocal.noise import TrackerUncertainty  # noqa: E402,F401
MAX_JOINTS = 12

_ORTHONORMAL_TOL = 1e-3
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*\Z")
FILE_NAME_MAX = 255                                      # bytes in one path component (ext4, XFS, APFS, NTFS)
MAX_NAME_CHARS = FILE_NAME_MAX - len("-YYYYmmdd-HHMMSS-NNNN")   # the name + a run directory's timestamp fit

Vec3 = tuple[float, float, float]
Matrix4 = tuple[tuple[float, float, float, float], ...]


# --------------------------------------------------------------------------- data


class FrozenMap(Mapping[str, Any]):
    """Immutable, hashable string-keyed mapping (driver options, effect params).

    Values are JSON-like scalars, tuples and nested ``FrozenMap``s.
    """

    __slots__ = ("_data",)

    def __init__(self, items: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()) -> None:
        self._data = dict(items)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __hash__(self) -> int:
        return hash(frozenset(self._data.items()))

    def __repr__(self) -> str:
        return f"FrozenMap({self._data!r})"


@dataclass(frozen=True, slots=True)
class JointConfig:
    """One row of the DH (or MDH) table; lengths in mm, angles in degrees.

    ``theta_deg`` is the offset added to the controller's joint value
    (YAML default 0). ``q_min_deg < q_max_deg`` are the controller's axis limits.
    """

    alpha_deg: float
    a_mm: float
    d_mm: float
    theta_deg: float
    q_min_deg: float
    q_max_deg: float


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """The robot arm and how to reach its controller.

    ``url`` scheme selects the driver (one of ``ROBOT_SCHEMES``). ``model`` (required, e.g. "ABB IRB
    2600-12/1.65") is compared with the model the controller reports at connect (a different model stops the run
    before the first move; vendor formatting is tolerated).
    ``hayati_joints``: 1-based joints whose axis is parallel to the next one
    (default none). ``repeatability_mm`` (ISO 9283 RP, default 0.05) and
    ``max_joint_speed_deg_s`` (default 30) feed noise and duration estimates.
    ``options`` (default empty) are passed to the driver unchanged.
    Gravity model of the physical effects (``robocal.effects.GravityModel``): ``link_masses_kg`` (one lumped mass
    per link, J1..Jn, default none), else ``mass_kg`` (the arm's datasheet mass: 70 % of it shared over the links
    as 0/38/43/13/4/1 %, default none), else the default masses of a ~130 kg arm (stiffnesses then scale with
    the true mass); ``gravity_direction_base`` (default [0, 0, -1], floor mount): gravity in the base frame, any
    direction for tilted, wall or ceiling mounts.
    Motion caps the driver enforces before any command is sent: ``max_tcp_speed_mm_s`` (default 250, at most
    ``datasheet_max_tcp_speed_mm_s``, the manufacturer's maximum TCP speed, when given) and
    ``max_joint_speed_pct`` (default 100, percent of the rated joint speed). ``first_pass_speed_pct``
    (default none): before measuring, traverse the whole plan once with both caps scaled to this percentage.
    """

    model: str
    url: str
    convention: str
    joints: tuple[JointConfig, ...]
    hayati_joints: tuple[int, ...]
    repeatability_mm: float
    max_joint_speed_deg_s: float
    options: Mapping[str, Any]
    max_tcp_speed_mm_s: float = 250.0
    max_joint_speed_pct: float = 100.0
    datasheet_max_tcp_speed_mm_s: float | None = None
    first_pass_speed_pct: float | None = None
    link_masses_kg: tuple[float, ...] | None = None
    mass_kg: float | None = None
    gravity_direction_base: Vec3 = (0.0, 0.0, -1.0)

    @property
    def n_joints(self) -> int:
        """Number of joints in the kinematic table."""
        return len(self.joints)


@dataclass(frozen=True, slots=True)
class ToolConfig:
    """The SMR on the flange: nominal centre in the flange frame (mm).

    Defaults: ``smr_diameter_mm`` 38.1 (1.5 in ball), ``payload_kg`` 0.
    A multi-SMR tool (seed 003) adds ``p_flange_smr2_mm`` and
    ``p_flange_smr3_mm`` (default ``None``; the third only with the second;
    centres at least ``smr_diameter_mm`` apart): every point then also logs
    the second and third SMR. ``payload_cog_flange_mm`` (default origin): centre of gravity of the payload
    in the flange frame (mm), sent to the controller with ``payload_kg``.
    """

    p_flange_smr_mm: Vec3
    smr_diameter_mm: float
    payload_kg: float
    p_flange_smr2_mm: Vec3 | None = None
    p_flange_smr3_mm: Vec3 | None = None
    payload_cog_flange_mm: Vec3 = (0.0, 0.0, 0.0)

    @property
    def smrs_mm(self) -> tuple[Vec3, ...]:
        """Centres of every configured SMR in the flange frame (mm), the main one first."""
        extra = (self.p_flange_smr2_mm, self.p_flange_smr3_mm)
        return (self.p_flange_smr_mm,) + tuple(p for p in extra if p is not None)


@dataclass(frozen=True, slots=True)
class MeasurementConfig:
    """How one point is measured.

    Defaults: ``samples`` 5 readings averaged (int >= 1), ``stability_mm`` 0.02
    max spread, ``settle_s`` 0.5 after the robot is in position, ``timeout_s``
    5.0 per reading, ``retries`` 3 per point (int >= 0) before the run pauses, ``reading_time_s`` 1.5
    (time one stationary tracker reading takes; duration estimates).
    """

    samples: int
    stability_mm: float
    settle_s: float
    timeout_s: float
    retries: int
    reading_time_s: float = 1.5


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """The laser tracker.

    ``url`` scheme selects the driver (one of ``TRACKER_SCHEMES``).
    ``model`` defaults to ``""`` (then not compared with the model the tracker reports at connect; a different
    model stops the run before the first move); ``position_in_base_mm`` (rough tracker
    position in the robot base frame, for aiming) defaults to ``None``;
    ``measurement`` takes the ``MeasurementConfig`` defaults; ``options``
    (default empty) are passed to the driver unchanged. What the tracker can see, for the poses an optimal
    plan may choose: ``max_range_mm`` (default none: not checked) from ``position_in_base_mm`` to the SMR, and
    ``max_incidence_deg`` (default 30, a 1.5 in SMR's acceptance half-angle) between the SMR's axis (the
    flange z-axis) and the line of sight (a pose is never refused for facing the tracker no worse than
    ``plan.tool_direction`` does at that position).
    """

    model: str
    url: str
    position_in_base_mm: Vec3 | None
    uncertainty: TrackerUncertainty
    measurement: MeasurementConfig
    options: Mapping[str, Any]
    max_range_mm: float | None = None
    max_incidence_deg: float = 30.0


@dataclass(frozen=True, slots=True)
class GridConfig:
    """Calibration grid: a box ``center_mm +- size_mm / 2`` in the robot base frame, sampled every ``step_mm``."""

    center_mm: Vec3
    size_mm: Vec3
    step_mm: float


@dataclass(frozen=True, slots=True)
class TestSetConfig:
    """Random validation points inside the grid box.

    Defaults: ``count`` 50 (int >= 0; 0 = no test set), ``seed`` 0 (int >= 0).
    """

    __test__ = False  # not a pytest test class despite the name

    count: int
    seed: int


@dataclass(frozen=True, slots=True)
class CheckPosesConfig:
    """Poses re-measured during the run (repeatability and drift).

    Defaults: ``count`` 0 (int >= 0), ``every_n_points`` 50 (int >= 1).
    """

    count: int
    every_n_points: int


@dataclass(frozen=True, slots=True)
class NestConfig:
    """One fixed reference nest: ``id`` (text), its approximate position ``p_base_mm`` in the robot base frame and,
    optionally, ``p_tracker_mm`` in the tracker frame (where a tracker without ``select_nest`` first aims)."""

    id: str
    p_base_mm: Vec3
    p_tracker_mm: Vec3 | None = None


@dataclass(frozen=True, slots=True)
class NestsConfig:
    """Fixed floor nests re-measured through the run (tracker-registration drift).

    ``points`` (default none) the nests; each is measured at the start, after every ``every_n_points``
    robot points (int >= 1, default 50) and at the end; the tracker aims at the nest, the robot does not
    move. The run pauses when a nest reads more than ``max_move_mm`` (default 0.2 mm) from its first
    reading (tracker or nest disturbed).
    """

    points: tuple[NestConfig, ...] = ()
    every_n_points: int = 50
    max_move_mm: float = 0.2


@dataclass(frozen=True, slots=True)
class Iso9283Config:
    """ISO 9283 pose test (``plan.kind: iso9283``): the largest cube inside the grid box (or ``edge_mm``),
    P1-P5 on its diagonal plane, ``cycles`` cycles (default 30).

    Defaults: ``cycles`` 30 (int >= 2), ``edge_mm`` 0 = the largest cube inside the grid box.
    """

    cycles: int = 30
    edge_mm: float = 0.0


@dataclass(frozen=True, slots=True)
class PoolConfig:
    """Candidate poses of an optimal plan (``plan.kind: optimal``): positions every ``step_mm`` in the grid box
    (default half the grid step), ``tool_direction`` and ``tilts`` (default 6) directions tilted by ``tilt_deg``
    (default 20; tilts need ``tracker.position_in_base_mm``) around it, each on ``q_ref_deg``'s IK branch and,
    with ``wrist_flip`` (default true), on the flipped-wrist branch."""

    step_mm: float | None = None
    tilt_deg: float = 20.0
    tilts: int = 6
    wrist_flip: bool = True


@dataclass(frozen=True, slots=True)
class PlanConfig:
    """What to measure.

    ``tool_direction``: fixed flange z-axis in the base frame (non-zero, not
    normalised). ``q_ref_deg``: reference joint configuration (one value per
    joint, inside the limits) selecting the IK branch. ``test`` and
    ``check_poses`` are optional. ``nests`` (optional) reference nests;
    ``order`` ``serpentine`` (default: grid order, each test point next to its
    nearest grid point) or ``random`` (calib and test points shuffled with
    ``order_seed``, default 0).
    ``check_poses`` are optional. ``keep_out`` (default none), ``envelope``
    (default none) and ``clearance_mm`` (default 25): see ``BoxConfig``.
    ``kind``: ``grid`` (default), ``optimal`` (``points`` calibration poses chosen from a candidate ``pool``
    by a D-optimal criterion, measured in a short tour) or ``iso9283``. ``stop: auto`` (optimal plans; default
    ``off``): refit after every ``block_points`` points (default 20) and stop when the predicted held-out RMS
    would improve by less than ``stop_gain_pct`` % of the noise floor (default 2) with the next block, or at
    ``max_points`` (default ``points``) or ``max_minutes`` (default none); then the test set is measured.
    """

    grid: GridConfig
    test: TestSetConfig
    tool_direction: Vec3
    q_ref_deg: tuple[float, ...]
    check_poses: CheckPosesConfig
    nests: NestsConfig = NestsConfig()
    order: str = "serpentine"
    order_seed: int = 0
    keep_out: tuple["BoxConfig", ...] = ()
    envelope: "BoxConfig | None" = None
    clearance_mm: float = 25.0
    kind: str = "grid"                          # grid | optimal (calibration campaign) | iso9283 (acceptance test)
    iso9283: Iso9283Config = Iso9283Config()
    points: int | None = None                   # optimal: calibration points
    pool: PoolConfig = PoolConfig()
    stop: str = "off"                           # off | auto
    max_points: int | None = None
    max_minutes: float | None = None
    block_points: int = 20
    stop_gain_pct: float = 2.0


@dataclass(frozen=True, slots=True)
class BoxConfig:
    """An axis-aligned box in the robot base frame (mm): ``min_mm`` < ``max_mm`` per axis; ``name`` for messages.

    ``plan.keep_out`` boxes must never be entered, ``plan.envelope`` never left, by the flange origin or any
    SMR centre (with ``plan.clearance_mm``, default 25) anywhere along the joint-interpolated path.
    """

    name: str
    min_mm: Vec3
    max_mm: Vec3


@dataclass(frozen=True, slots=True)
class CalibrationConfig:
    """Identification settings (the whole section is optional).

    Defaults: ``method`` lm, ``weights`` igg3 (robust_ridge only), ``k0`` 1.5 < ``k1`` 2.5
    (IGG-III thresholds, in units of sigma), ``ridge_mu`` 1e-6 (>= 0),
    ``residual`` auto, ``idw_power`` 2.0 (> 0), ``idw_k_nearest`` 8 (int >= 1),
    ``outliers`` local, ``effects`` auto, ``cv_folds`` 5 (int >= 2).

    ``outliers``: ``local`` excludes a point only as a measurement fault (residual isolated against its
    neighbours in joint space and in the workspace, tracker statistics, repeats); ``none`` keeps all.
    ``effects``: ``auto`` (forward selection of physical effects by k-fold CV on the calibration points),
    ``none``, or a list of effect specs (``name`` in ``MODEL_EFFECT_NAMES``, optional ``params`` with the
    factory's keys: joints, joint, harmonics, tau_s, link_masses_kg) that become parameters of the model.
    ``residual`` ``auto`` chooses none / idw / gpr by k-fold CV and keeps a layer only on a significant gain.

    ``residual`` (one of ``RESIDUAL_MODELS``) is the layer fitted on top of
    the kinematic model: ``idw`` inverse distance weighting over positions
    (seed 000), ``gpr`` Gaussian-process regression over joint angles, one
    model per base-frame axis (seed 003; the payload becomes an extra input
    when it varies across the calibration points; the report gives the
    predictive standard deviation of every test point), ``none`` no layer.
    ``idw_*`` apply to ``idw`` only.

    ``joints`` (one of ``JOINT_SETS``, default auto) which joint values drive
    the model when the data holds both commanded (``qc1..qcn``) and read-back
    (``q1..qn``) joints: ``auto`` takes the commanded ones when read-back minus
    command is significantly above the encoder noise or correlates with the
    last move, unless a geometric fit with the read-back ones is clearly better
    (campaign/calibrate/prepare.py), else the read-back ones.
    """

    method: str
    weights: str
    k0: float
    k1: float
    ridge_mu: float
    residual: str
    idw_power: float
    idw_k_nearest: int
    joints: str = "auto"
    outliers: str = "local"
    effects: str | tuple["EffectSpec", ...] = "auto"
    cv_folds: int = 5


@dataclass(frozen=True, slots=True)
class CorrectionConfig:
    """Target correction (seed 001) and its safety bounds.

    ``generator`` pseudo-target generator or ``ensemble`` (multiply + quaternion, default);
    ``error`` position | pose; ``threshold_mm`` (default 1e-4) and ``max_iterations`` (20) stop the
    iteration; a corrected target is rejected (never written, never moved to) when a joint changes by more
    than ``max_joint_correction_deg`` (default 0.5) or the command moves more than
    ``max_position_correction_mm`` (default 5.0) from the target. ``closed_loop_iterations`` (default 2)
    measured iterations in ``campaign verify``; a measured error is only corrected when it exceeds
    ``significance`` (default 3.0) times the point's standard uncertainty (do not chase noise).
    """

    generator: str
    error: str
    threshold_mm: float
    max_iterations: int
    max_joint_correction_deg: float
    max_position_correction_mm: float
    closed_loop_iterations: int
    significance: float


@dataclass(frozen=True, slots=True)
class FaultsConfig:
    """Per-reading fault probabilities of the mock tracker, each in [0, 1] (default 0)."""

    beam_break_probability: float
    timeout_probability: float
    garbage_probability: float


@dataclass(frozen=True, slots=True)
class EffectSpec:
    """One non-geometric error effect of the simulated robot.

    ``name`` in ``EFFECT_NAMES``; ``scale`` >= 0 (default 1); ``params``
    (default empty) are effect-specific. In YAML an effect is either a mapping
    ``{name: ..., scale: ..., params: {...}}`` or just its name.
    """

    name: str
    scale: float
    params: Mapping[str, Any]


@dataclass(frozen=True, slots=True)
class SimulationConfig:
    """The truth behind ``mock://`` drivers (ignored by real drivers).

    Defaults: ``seed`` 0, ``geometric_error_scale`` 1.0 (>= 0),
    ``T_tracker_base`` maps base-frame points to tracker-frame points (mm) and
    defaults to a pure translation putting the tracker at
    ``tracker.position_in_base_mm`` (identity if that is absent),
    ``p_flange_smr_mm`` (true SMR offset) defaults to ``tool.p_flange_smr_mm``,
    ``effects`` none, ``motion_time_s`` 0 (instant moves), ``faults`` none.

    Read-back and tracker phenomena (all default 0 = off):
    ``readback_lag_deg_per_deg`` (one number per joint): the mock robot reports
    ``q_read = q_cmd + lag_j * (last move of joint j) + N(0, readback_noise_deg)``
    while it really stands at ``q_cmd``; ``tracker_drift_mm_per_h`` and
    ``tracker_drift_urad_per_h`` (3 numbers each, tracker frame): every tracker
    reading (SMRs and nests) is displaced by ``u(t) * (v + w x p)``, u = t in
    hours, or with ``tracker_drift_tau_s`` > 0 a settling curve
    ``tau_h * (1 - exp(-t / tau))`` with the same initial rate.
    """

    seed: int
    geometric_error_scale: float
    T_tracker_base: Matrix4
    p_flange_smr_mm: Vec3
    effects: tuple[EffectSpec, ...]
    motion_time_s: float
    faults: FaultsConfig
    readback_lag_deg_per_deg: tuple[float, ...] = ()
    readback_noise_deg: float = 0.0
    tracker_drift_mm_per_h: Vec3 = (0.0, 0.0, 0.0)
    tracker_drift_urad_per_h: Vec3 = (0.0, 0.0, 0.0)
    tracker_drift_tau_s: float = 0.0


@dataclass(frozen=True, slots=True)
class OutputConfig:
    """Where runs are written: ``dir`` (default ``runs``, relative to the working directory)."""

    dir: str


@dataclass(frozen=True, slots=True)
class AcceptanceConfig:
    """Optional pass/fail criterion on the final model's held-out test set (mm): ``max_rms_mm`` bounds its RMS,
    ``max_mm`` its largest error; either may be omitted, and without the section no verdict is given."""

    max_rms_mm: float | None = None
    max_mm: float | None = None

    @property
    def configured(self) -> bool:
        return self.max_rms_mm is not None or self.max_mm is not None


@dataclass(frozen=True, slots=True)
class CampaignConfig:
    """A whole campaign file.

    ``name`` is used in run directory names (letters, digits, ``_ . -``).
    ``source_path`` is the path the file was loaded from, as given;
    ``sha256`` is the hex digest of the file bytes (detects a changed config
    on resume). ``calibration``, ``simulation``, ``output`` and ``acceptance`` are optional;
    ``acceptance: {max_rms_mm, max_mm}`` is the pass/fail criterion of the held-out test set (mm,
    :class:`AcceptanceConfig`; absent: "no acceptance criterion configured").
    """

    name: str
    robot: RobotConfig
    tool: ToolConfig
    tracker: TrackerConfig
    plan: PlanConfig
    calibration: CalibrationConfig
    correction: CorrectionConfig
    simulation: SimulationConfig
    output: OutputConfig
    source_path: str
    sha256: str
    acceptance: AcceptanceConfig = AcceptanceConfig()

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict (tuples become lists, mappings dicts)."""
        return _to_plain(self)


def _to_plain(value: Any) -> Any:
    """Recursively convert dataclasses, tuples and mappings to dicts/lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _to_plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_to_plain(v) for v in value]
    return value


