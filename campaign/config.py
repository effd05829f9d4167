"""Campaign configuration: one YAML file -> validated, frozen dataclasses.

``configs/irb2600.yaml`` is the reference schema. The YAML keys of a section
are exactly the field names of its dataclass (``CampaignConfig`` adds
``source_path`` and ``sha256``), so ``CampaignConfig.to_dict()`` has the shape
of the YAML file with every default filled in.

Units are in the key names (``_mm``, ``_deg``, ``_s``, ``_um``, ...). Joint
values are the controller's, in degrees; ``theta_DH = q + theta_deg``.

Every validation failure raises :class:`campaign.errors.ConfigError` naming
the file, the dotted key path (0-based list indices, e.g.
``robot.joints[2].a_mm``) and what was expected versus what was found.
A key given as ``null`` counts as absent when the key is optional.
"""

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
from campaign.yaml_limits import load_limited, read_limited

__all__ = [
    "CALIBRATION_METHODS",
    "CONVENTIONS",
    "EFFECT_NAMES",
    "MAX_JOINTS",
    "RESIDUAL_MODELS",
    "ROBOT_SCHEMES",
    "TRACKER_SCHEMES",
    "WEIGHT_FUNCTIONS",
    "CalibrationConfig",
    "CampaignConfig",
    "CheckPosesConfig",
    "EffectSpec",
    "FaultsConfig",
    "FrozenMap",
    "GridConfig",
    "JointConfig",
    "MeasurementConfig",
    "NestConfig",
    "NestsConfig",
    "OutputConfig",
    "PlanConfig",
    "RobotConfig",
    "SimulationConfig",
    "TestSetConfig",
    "ToolConfig",
    "BoxConfig",
    "TrackerConfig",
    "TrackerUncertainty",
    "load_config",
    "parse_config",
]

from drivers.registry import ROBOT_SCHEMES, TRACKER_SCHEMES  # noqa: E402  (the registry owns the url schemes)
CONVENTIONS = ("dh", "mdh")
CALIBRATION_METHODS = ("robust_ridge", "lm")
WEIGHT_FUNCTIONS = ("igg3", "huber", "none")
RESIDUAL_MODELS = ("idw", "gpr", "none", "auto")
OUTLIER_SCREENS = ("local", "none")
MODEL_EFFECT_NAMES = ("joint_compliance", "payload_deflection", "gear_cyclic", "backlash", "thermal_drift",
                      "axis_coupling")
JOINT_SETS = ("auto", "commanded", "readback")
PLAN_ORDERS = ("serpentine", "random")
CORRECTION_GENERATORS = ("ensemble", "yin", "fixed", "add", "multiply", "euler_zyz", "euler_xyz", "quaternion")
ERROR_FUNCTIONS = ("position", "pose")
from robocal.effects import SIMULATED_EFFECTS as EFFECT_NAMES  # noqa: E402  (one owner: robocal.effects)
MAX_JOINTS = 12

_ORTHONORMAL_TOL = 1e-3
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*\Z")

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

    ``url`` scheme selects the driver (one of ``ROBOT_SCHEMES``).
    ``hayati_joints``: 1-based joints whose axis is parallel to the next one
    (default none). ``repeatability_mm`` (ISO 9283 RP, default 0.05) and
    ``max_joint_speed_deg_s`` (default 30) feed noise and duration estimates.
    ``options`` (default empty) are passed to the driver unchanged.
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
class TrackerUncertainty:
    """Tracker MPE ``a + b * distance`` per direction, expanded with ``coverage_k``.

    ``*_a_um`` in micrometres (> 0), ``*_b_um_per_m`` in micrometres per metre
    (>= 0), ``coverage_k`` > 0 (default 2).
    """

    transverse_a_um: float
    transverse_b_um_per_m: float
    range_a_um: float
    range_b_um_per_m: float
    coverage_k: float


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
    ``model`` defaults to ``""``; ``position_in_base_mm`` (rough tracker
    position in the robot base frame, for aiming) defaults to ``None``;
    ``measurement`` takes the ``MeasurementConfig`` defaults; ``options``
    (default empty) are passed to the driver unchanged.
    """

    model: str
    url: str
    position_in_base_mm: Vec3 | None
    uncertainty: TrackerUncertainty
    measurement: MeasurementConfig
    options: Mapping[str, Any]


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
    kind: str = "grid"                          # grid (calibration campaign) | iso9283 (acceptance test)
    iso9283: Iso9283Config = Iso9283Config()


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
    (campaign/prepare.py), else the read-back ones.
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
class CampaignConfig:
    """A whole campaign file.

    ``name`` is used in run directory names (letters, digits, ``_ . -``).
    ``source_path`` is the path the file was loaded from, as given;
    ``sha256`` is the hex digest of the file bytes (detects a changed config
    on resume). ``calibration``, ``simulation`` and ``output`` are optional.
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


# --------------------------------------------------------------------------- loading


def load_config(path: str | Path) -> CampaignConfig:
    """Read, parse and validate the campaign file at ``path``.

    Raises ``ConfigError`` for a missing/unreadable file, malformed YAML or
    any schema violation.
    """
    file = str(path)
    try:
        data = read_limited(path)
    except FileNotFoundError:
        raise ConfigError(file, "", "file not found") from None
    except IsADirectoryError:
        raise ConfigError(file, "", "is a directory, expected a YAML file") from None
    except OSError as exc:
        raise ConfigError(file, "", f"cannot read file: {exc.strerror or exc}") from None
    return parse_config(data, file)


def parse_config(data: bytes, file: str) -> CampaignConfig:
    """Validate campaign YAML given as bytes; ``file`` names it in errors and ``source_path``."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(file, "", f"not UTF-8 text (bad byte at offset {exc.start})") from None
    doc = _parse_yaml(text, file)
    if doc is None:
        raise ConfigError(file, "", "empty config file (expected a mapping of sections)")
    if not isinstance(doc, dict):
        raise ConfigError(file, "", f"top level must be a mapping of sections, got {_describe(doc)}")
    cfg = _campaign(_Reader(doc, file, "", _keys(CampaignConfig, "source_path", "sha256")),
                    sha256=hashlib.sha256(data).hexdigest())
    from campaign.config_checks import check_config  # cross-key checks: drivers, sizes, Hayati, effects

    check_config(cfg)
    return cfg


class _StrictSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also rejects duplicate mapping keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, Iterable) and not isinstance(key, str):
                continue  # unhashable: the base class reports it
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _parse_yaml(text: str, file: str) -> Any:
    """Safe-load YAML text; syntax errors become one-line ``ConfigError``s."""
    try:
        return load_limited(text, _StrictSafeLoader, file)  # size and alias-expansion limits
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "syntax error"
        if mark is None:
            raise ConfigError(file, "", f"malformed YAML: {problem}") from None
        raise ConfigError.malformed_yaml(file, mark.line + 1, mark.column + 1, problem) from None
    except yaml.YAMLError as exc:
        raise ConfigError(file, "", f"malformed YAML: {exc}") from None


# --------------------------------------------------------------------------- reader

_REQUIRED: Any = object()


def _keys(cls: type, *exclude: str) -> tuple[str, ...]:
    """YAML keys of a section: the dataclass field names."""
    return tuple(f.name for f in dataclasses.fields(cls) if f.name not in exclude)


def _describe(value: Any) -> str:
    """Short YAML-flavoured rendering of a found value for error messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        text = repr(value)
        return text if len(text) <= 40 else text[:37] + "...'"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, dict):
        return "a mapping"
    return f"a {type(value).__name__}"


def _fmt(x: float) -> str:
    """Compact number for messages (``1450`` rather than ``1450.0``)."""
    return f"{x:.6g}"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _bound_text(noun: str, positive: bool, lo: float | None, hi: float | None) -> str:
    """E.g. ``a positive number``, ``an integer >= 1``, ``a number in [0, 1]``."""
    if positive:
        return f"a positive {noun}"
    article = "an" if noun[0] in "aeiou" else "a"
    if lo is not None and hi is not None:
        return f"{article} {noun} in [{_fmt(lo)}, {_fmt(hi)}]"
    if lo is not None:
        return f"{article} {noun} >= {_fmt(lo)}"
    if hi is not None:
        return f"{article} {noun} <= {_fmt(hi)}"
    return f"{article} {noun}"


def _number_hint(value: Any) -> str:
    """Explain PyYAML's YAML 1.1 habit of reading ``1e-6`` as a string."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return " (YAML reads exponents without a dot as text: write e.g. 1.0e-6)"
    return ""


class _Reader:
    """Typed, validated access to one YAML mapping.

    Knows its file and key path; rejects keys outside ``allowed`` on creation.
    Getters take ``default``: omitted = the key is required.
    """

    def __init__(self, data: Any, file: str, path: str, allowed: Sequence[str]) -> None:
        self.file = file
        self.path = path
        if not isinstance(data, dict):
            raise ConfigError(file, path, f"expected a mapping, got {_describe(data)}")
        self.data = data
        for key in data:
            if key not in allowed:
                raise self.error(str(key), f"unknown key (expected one of: {', '.join(sorted(allowed))})")

    # -- plumbing
    def key_path(self, key: str | int) -> str:
        """Dotted path of a child key (or ``[i]`` for an int index)."""
        if isinstance(key, int):
            return f"{self.path}[{key}]"
        return f"{self.path}.{key}" if self.path else key

    def error(self, key: str | int | None, message: str) -> ConfigError:
        """A ``ConfigError`` at ``key`` (``None`` = this section itself)."""
        return ConfigError(self.file, self.path if key is None else self.key_path(key), message)

    def _get(self, key: str, default: Any) -> tuple[Any, bool]:
        """(value, given); raises if a required key is absent."""
        value = self.data.get(key)
        if key in self.data and (value is not None or default is _REQUIRED):
            return value, True
        if default is _REQUIRED:
            raise self.error(None, f"missing required key '{key}'")
        return default, False

    # -- scalars
    def number(self, key: str, default: Any = _REQUIRED, *, positive: bool = False,
               lo: float | None = None, hi: float | None = None) -> float:
        """A finite float (int accepted, bool not) within the given bounds."""
        value, _ = self._get(key, default)
        return _check_number(value, self.error_at(key), positive=positive, lo=lo, hi=hi)

    def integer(self, key: str, default: Any = _REQUIRED, *,
                lo: int | None = None, hi: int | None = None) -> int:
        """An int (not bool, not float) within ``[lo, hi]``."""
        value, _ = self._get(key, default)
        return _check_integer(value, self.error_at(key), lo=lo, hi=hi)

    def string(self, key: str, default: Any = _REQUIRED, *, allow_empty: bool = False) -> str:
        """A string, non-blank unless ``allow_empty``."""
        value, _ = self._get(key, default)
        if not isinstance(value, str) or (not value.strip() and not allow_empty):
            raise self.error(key, f"expected a non-empty string, got {_describe(value)}")
        return value

    def choice(self, key: str, options: Iterable[str], default: Any = _REQUIRED) -> str:
        """One of ``options``."""
        value, _ = self._get(key, default)
        options = tuple(options)
        if not isinstance(value, str) or value not in options:
            raise self.error(key, f"expected one of: {', '.join(options)}, got {_describe(value)}")
        return value

    def url(self, key: str, schemes: Iterable[str]) -> str:
        """A driver URL ``scheme://...`` whose scheme is one of ``schemes``."""
        value = self.string(key)
        known = ", ".join(sorted(schemes))
        scheme, sep, _ = value.partition("://")
        if not sep:
            raise self.error(key, f"expected a driver URL like 'mock://...' (drivers: {known}), got {_describe(value)}")
        if scheme not in schemes:
            raise self.error(key, f"unknown driver {scheme!r} (expected one of: {known})")
        return value

    # -- containers
    def vector(self, key: str, n: int, default: Any = _REQUIRED, *,
               positive: bool = False) -> tuple[float, ...] | None:
        """A list of exactly ``n`` finite numbers (``None`` only if that is the default)."""
        value, given = self._get(key, default)
        if value is None and not given:
            return None
        return _check_vector(value, n, self.key_path(key), self.file, positive=positive)

    def integers(self, key: str, default: Any = _REQUIRED, *,
                 lo: int | None = None, hi: int | None = None) -> tuple[int, ...]:
        """A list of distinct ints within ``[lo, hi]``."""
        value, _ = self._get(key, default)
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"expected a list of integers, got {_describe(value)}")
        sub = self.child_list(key)
        out = tuple(_check_integer(v, sub.error_at(i), lo=lo, hi=hi) for i, v in enumerate(value))
        for i, v in enumerate(out):
            if v in out[:i]:
                raise sub.error(i, f"duplicate value {v}")
        return out

    def matrix(self, key: str, rows: int, cols: int, default: Any = _REQUIRED) -> tuple[tuple[float, ...], ...]:
        """A ``rows`` x ``cols`` list of lists of finite numbers."""
        value, _ = self._get(key, default)
        shape = f"expected a {rows}x{cols} matrix (a list of {rows} lists of {cols} numbers)"
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"{shape}, got {_describe(value)}")
        if len(value) != rows:
            raise self.error(key, f"{shape}, got {len(value)} rows")
        path = self.key_path(key)
        return tuple(_check_vector(row, cols, f"{path}[{i}]", self.file) for i, row in enumerate(value))

    def mapping(self, key: str, default: Any = _REQUIRED) -> FrozenMap:
        """A free-form mapping of JSON-like values (string keys), frozen."""
        value, _ = self._get(key, default)
        if not isinstance(value, dict):
            raise self.error(key, f"expected a mapping, got {_describe(value)}")
        return _freeze(value, self.key_path(key), self.file)

    def section(self, key: str, cls: type, *, required: bool = True) -> _Reader:
        """Reader for a nested mapping whose allowed keys are ``cls``'s fields."""
        value, _ = self._get(key, _REQUIRED if required else {})
        return _Reader(value, self.file, self.key_path(key), _keys(cls))

    def items(self, key: str, default: Any = _REQUIRED, *,
              min_len: int = 0, max_len: int | None = None, what: str = "items") -> list[Any]:
        """A list (raw elements) with a length check; see ``child_list`` for element paths."""
        value, _ = self._get(key, default)
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f"expected a list of {what}, got {_describe(value)}")
        if len(value) < min_len or (max_len is not None and len(value) > max_len):
            span = f"{min_len} to {max_len}" if max_len is not None else f"at least {min_len}"
            raise self.error(key, f"expected a list of {span} {what}, got {len(value)}")
        return list(value)

    def child_list(self, key: str) -> _ListPath:
        """Error helper for elements of the list at ``key``."""
        return _ListPath(self.file, self.key_path(key))

    def error_at(self, key: str | int) -> Callable[[str], ConfigError]:
        """Factory of errors at ``key`` (for the shared checkers)."""
        return lambda message: self.error(key, message)


@dataclass(frozen=True, slots=True)
class _ListPath:
    """Key-path helper for the elements of a list."""

    file: str
    path: str

    def key_path(self, index: int) -> str:
        return f"{self.path}[{index}]"

    def error(self, index: int, message: str) -> ConfigError:
        return ConfigError(self.file, self.key_path(index), message)

    def error_at(self, index: int) -> Callable[[str], ConfigError]:
        return lambda message: self.error(index, message)

    def reader(self, index: int, value: Any, cls: type) -> _Reader:
        return _Reader(value, self.file, self.key_path(index), _keys(cls))


def _check_number(value: Any, error: Callable[[str], ConfigError], *, positive: bool = False,
                  lo: float | None = None, hi: float | None = None) -> float:
    """Validate one number; ``error(message)`` builds the exception."""
    expected = _bound_text("number", positive, lo, hi)
    if not _is_number(value):
        raise error(f"expected {expected}, got {_describe(value)}{_number_hint(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise error(f"expected a finite number, got {_describe(value)}")
    if (positive and x <= 0) or (lo is not None and x < lo) or (hi is not None and x > hi):
        raise error(f"expected {expected}, got {_describe(value)}")
    return x


def _check_integer(value: Any, error: Callable[[str], ConfigError], *,
                   lo: int | None = None, hi: int | None = None) -> int:
    """Validate one integer (bools and floats rejected)."""
    expected = _bound_text("integer", False, lo, hi)
    if not isinstance(value, int) or isinstance(value, bool):
        raise error(f"expected {expected}, got {_describe(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise error(f"expected {expected}, got {value}")
    return value


def _check_vector(value: Any, n: int, path: str, file: str, *, positive: bool = False) -> tuple[float, ...]:
    """Validate a list of exactly ``n`` finite numbers at ``path``."""
    noun = "positive numbers" if positive else "numbers"
    if not isinstance(value, (list, tuple)):
        raise ConfigError(file, path, f"expected a list of {n} {noun}, got {_describe(value)}")
    if len(value) != n:
        raise ConfigError(file, path, f"expected a list of {n} {noun}, got {len(value)}")
    where = _ListPath(file, path)
    return tuple(_check_number(v, where.error_at(i), positive=positive) for i, v in enumerate(value))


def _freeze(value: Any, path: str, file: str) -> Any:
    """Deep-freeze JSON-like YAML data (dict -> FrozenMap, list -> tuple)."""
    if isinstance(value, dict):
        for key in value:
            if not isinstance(key, str):
                raise ConfigError(file, path, f"expected string keys, got key {_describe(key)}")
        return FrozenMap((k, _freeze(v, f"{path}.{k}", file)) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return tuple(_freeze(v, f"{path}[{i}]", file) for i, v in enumerate(value))
    if value is None or isinstance(value, (str, bool, int)):
        return value
    if isinstance(value, float) and math.isfinite(value):
        return value
    raise ConfigError(file, path, f"expected JSON-like data (text, numbers, lists, mappings), got {_describe(value)}")


# --------------------------------------------------------------------------- sections


def _campaign(r: _Reader, sha256: str) -> CampaignConfig:
    """Top level: sections in dependency order (robot -> tool -> tracker -> plan -> simulation)."""
    name = r.string("name")
    if not _NAME_RE.match(name):
        raise r.error("name", f"expected letters, digits, '_', '.' or '-' (it names run directories), got {_describe(name)}")
    robot = _robot(r.section("robot", RobotConfig))
    tool = _tool(r.section("tool", ToolConfig))
    tracker = _tracker(r.section("tracker", TrackerConfig))
    plan = _plan(r.section("plan", PlanConfig), robot, tool)
    return CampaignConfig(
        name=name,
        robot=robot,
        tool=tool,
        tracker=tracker,
        plan=plan,
        calibration=_calibration(r.section("calibration", CalibrationConfig, required=False)),
        correction=_correction(r.section("correction", CorrectionConfig, required=False)),
        simulation=_simulation(r.section("simulation", SimulationConfig, required=False), tool, tracker,
                               robot.n_joints),
        output=_output(r.section("output", OutputConfig, required=False)),
        source_path=r.file,
        sha256=sha256,
    )


def _robot(r: _Reader) -> RobotConfig:
    model = r.string("model")
    url = r.url("url", ROBOT_SCHEMES)
    convention = r.choice("convention", CONVENTIONS)
    rows = r.items("joints", min_len=1, max_len=MAX_JOINTS, what="joint mappings")
    where = r.child_list("joints")
    joints = tuple(_joint(where.reader(i, row, JointConfig)) for i, row in enumerate(rows))
    from campaign.config_checks import check_joint_count  # before the plan's checks use the joints

    check_joint_count(len(joints), r.file)
    return RobotConfig(
        model=model,
        url=url,
        convention=convention,
        joints=joints,
        hayati_joints=r.integers("hayati_joints", [], lo=1, hi=len(joints)),
        repeatability_mm=r.number("repeatability_mm", 0.05, lo=0.0),
        max_joint_speed_deg_s=r.number("max_joint_speed_deg_s", 30.0, positive=True),
        options=r.mapping("options", {}),
        **_motion_caps(r),
    )


def _motion_caps(r: _Reader) -> dict[str, Any]:
    """Speed caps: the TCP cap must not exceed the datasheet maximum (mm/s) when one is given."""
    given = r.data.get("datasheet_max_tcp_speed_mm_s") is not None
    datasheet = r.number("datasheet_max_tcp_speed_mm_s", positive=True) if given else None
    tcp = r.number("max_tcp_speed_mm_s", 250.0, positive=True)
    if datasheet is not None and tcp > datasheet:
        raise r.error("max_tcp_speed_mm_s", f"{_fmt(tcp)} mm/s exceeds the robot's datasheet maximum "
                                            f"datasheet_max_tcp_speed_mm_s = {_fmt(datasheet)} mm/s")
    first = r.data.get("first_pass_speed_pct")
    return {"max_tcp_speed_mm_s": tcp, "datasheet_max_tcp_speed_mm_s": datasheet,
            "max_joint_speed_pct": r.number("max_joint_speed_pct", 100.0, positive=True, hi=100.0),
            "first_pass_speed_pct": None if first is None else r.number("first_pass_speed_pct", positive=True,
                                                                        hi=100.0)}


def _joint(r: _Reader) -> JointConfig:
    q_min = r.number("q_min_deg")
    q_max = r.number("q_max_deg")
    if q_min >= q_max:
        raise r.error("q_max_deg", f"expected a number > q_min_deg = {_fmt(q_min)}, got {_fmt(q_max)}")
    return JointConfig(
        alpha_deg=r.number("alpha_deg"),
        a_mm=r.number("a_mm"),
        d_mm=r.number("d_mm"),
        theta_deg=r.number("theta_deg", 0.0),
        q_min_deg=q_min,
        q_max_deg=q_max,
    )


def _tool(r: _Reader) -> ToolConfig:
    tool = ToolConfig(
        p_flange_smr_mm=r.vector("p_flange_smr_mm", 3),
        smr_diameter_mm=r.number("smr_diameter_mm", 38.1, positive=True),
        payload_kg=r.number("payload_kg", 0.0, lo=0.0),
        p_flange_smr2_mm=r.vector("p_flange_smr2_mm", 3, None),
        p_flange_smr3_mm=r.vector("p_flange_smr3_mm", 3, None),
        payload_cog_flange_mm=r.vector("payload_cog_flange_mm", 3, [0.0, 0.0, 0.0]),
    )
    _check_smrs(tool, r)
    return tool


def _check_smrs(tool: ToolConfig, r: _Reader) -> None:
    """The third SMR needs the second; no two SMR centres closer than one ball diameter (mm)."""
    if tool.p_flange_smr3_mm is not None and tool.p_flange_smr2_mm is None:
        raise r.error("p_flange_smr3_mm", "a third SMR needs p_flange_smr2_mm (the second SMR)")
    keys = ("p_flange_smr_mm", "p_flange_smr2_mm", "p_flange_smr3_mm")
    smrs = tool.smrs_mm
    for j in range(1, len(smrs)):
        for i in range(j):
            gap = math.dist(smrs[i], smrs[j])
            if gap < tool.smr_diameter_mm:
                raise r.error(keys[j], f"SMR centre {gap:.1f} mm from {keys[i]}: closer than one ball "
                                       f"(smr_diameter_mm = {_fmt(tool.smr_diameter_mm)})")


def _tracker(r: _Reader) -> TrackerConfig:
    return TrackerConfig(
        model=r.string("model", "", allow_empty=True),
        url=r.url("url", TRACKER_SCHEMES),
        position_in_base_mm=r.vector("position_in_base_mm", 3, None),
        uncertainty=_uncertainty(r.section("uncertainty", TrackerUncertainty)),
        measurement=_measurement(r.section("measurement", MeasurementConfig, required=False)),
        options=r.mapping("options", {}),
    )


def _uncertainty(r: _Reader) -> TrackerUncertainty:
    return TrackerUncertainty(
        transverse_a_um=r.number("transverse_a_um", positive=True),
        transverse_b_um_per_m=r.number("transverse_b_um_per_m", lo=0.0),
        range_a_um=r.number("range_a_um", positive=True),
        range_b_um_per_m=r.number("range_b_um_per_m", lo=0.0),
        coverage_k=r.number("coverage_k", 2.0, positive=True),
    )


def _measurement(r: _Reader) -> MeasurementConfig:
    return MeasurementConfig(
        samples=r.integer("samples", 5, lo=1),
        stability_mm=r.number("stability_mm", 0.02, positive=True),
        settle_s=r.number("settle_s", 0.5, lo=0.0),
        timeout_s=r.number("timeout_s", 5.0, positive=True),
        retries=r.integer("retries", 3, lo=0),
        reading_time_s=r.number("reading_time_s", 1.5, positive=True),
    )


def _plan(r: _Reader, robot: RobotConfig, tool: ToolConfig) -> PlanConfig:
    grid = _grid(r.section("grid", GridConfig))
    _check_reach(grid, robot, tool, r)
    direction = r.vector("tool_direction", 3)
    if math.hypot(*direction) < 1e-9:
        raise r.error("tool_direction", "expected a non-zero direction vector, got [0, 0, 0]")
    q_ref = r.vector("q_ref_deg", robot.n_joints)
    _check_q_ref(q_ref, robot.joints, r.child_list("q_ref_deg"))
    return PlanConfig(
        grid=grid,
        test=_test_set(r.section("test", TestSetConfig, required=False)),
        tool_direction=direction,
        q_ref_deg=q_ref,
        check_poses=_check_poses(r.section("check_poses", CheckPosesConfig, required=False)),
        nests=_nests(r.section("nests", NestsConfig, required=False)),
        order=r.choice("order", PLAN_ORDERS, "serpentine"),
        order_seed=r.integer("order_seed", 0, lo=0),
        keep_out=_keep_out(r),
        envelope=None if r.data.get("envelope") is None else _box(r.section("envelope", BoxConfig), "envelope"),
        clearance_mm=r.number("clearance_mm", 25.0, lo=0.0),
        kind=r.choice("kind", ("grid", "iso9283"), "grid"),
        iso9283=_iso9283(r.section("iso9283", Iso9283Config, required=False)),
    )


def _keep_out(r: _Reader) -> tuple[BoxConfig, ...]:
    """``plan.keep_out``: a list of boxes ``{name, min_mm, max_mm}`` (base frame, mm)."""
    where = r.child_list("keep_out")
    return tuple(_box(where.reader(i, item, BoxConfig), f"keep_out[{i}]")
                 for i, item in enumerate(r.items("keep_out", [], what="boxes")))


def _box(r: _Reader, default_name: str) -> BoxConfig:
    lo, hi = r.vector("min_mm", 3), r.vector("max_mm", 3)
    for k, axis in enumerate("xyz"):
        if hi[k] <= lo[k]:
            raise r.error("max_mm", f"expected max_mm.{axis} > min_mm.{axis} = {_fmt(lo[k])}, got {_fmt(hi[k])}")
    return BoxConfig(name=r.string("name", default_name), min_mm=lo, max_mm=hi)


def _nests(r: _Reader) -> NestsConfig:
    """``plan.nests``: ids unique and non-empty, positions in the base frame (mm)."""
    where = r.child_list("points")
    points: list[NestConfig] = []
    for i, item in enumerate(r.items("points", [], what="nests")):
        nr = where.reader(i, item, NestConfig)
        nest = NestConfig(id=nr.string("id"), p_base_mm=nr.vector("p_base_mm", 3),
                          p_tracker_mm=nr.vector("p_tracker_mm", 3, None))
        if not _NAME_RE.match(nest.id):
            raise nr.error("id", f"expected letters, digits, '_', '.' or '-', got {_describe(nest.id)}")
        if any(n.id == nest.id for n in points):
            raise nr.error("id", f"duplicate nest id {nest.id!r}")
        points.append(nest)
    return NestsConfig(points=tuple(points), every_n_points=r.integer("every_n_points", 50, lo=1),
                       max_move_mm=r.number("max_move_mm", 0.2, positive=True))


def _iso9283(r: _Reader) -> Iso9283Config:
    return Iso9283Config(cycles=r.integer("cycles", 30, lo=2), edge_mm=r.number("edge_mm", 0.0, lo=0.0))


def _grid(r: _Reader) -> GridConfig:
    return GridConfig(
        center_mm=r.vector("center_mm", 3),
        size_mm=r.vector("size_mm", 3, positive=True),
        step_mm=r.number("step_mm", positive=True),
    )


def _check_reach(grid: GridConfig, robot: RobotConfig, tool: ToolConfig, plan: _Reader) -> None:
    """Every box corner must lie within sum(|a| + |d|) + |p_flange_smr| of the base origin (mm)."""
    reach = sum(abs(j.a_mm) + abs(j.d_mm) for j in robot.joints) + math.hypot(*tool.p_flange_smr_mm)
    half = [s / 2 for s in grid.size_mm]
    corner = tuple(c + (h if c >= 0 else -h) for c, h in zip(grid.center_mm, half))  # farthest corner
    distance = math.hypot(*corner)
    if distance > reach:
        coords = ", ".join(_fmt(c) for c in corner)
        raise ConfigError(
            plan.file,
            plan.key_path("grid") + ".center_mm",
            f"box corner ({coords}) mm is outside the robot's reach "
            f"(max {reach:.1f} mm, corner at {distance:.1f} mm)",
        )


def _check_q_ref(q_ref: Sequence[float], joints: Sequence[JointConfig], where: _ListPath) -> None:
    """Each reference joint value must lie inside its joint's limits (deg)."""
    for i, (q, joint) in enumerate(zip(q_ref, joints)):
        if not joint.q_min_deg <= q <= joint.q_max_deg:
            raise where.error(
                i,
                f"{_fmt(q)} deg is outside joint {i + 1} limits "
                f"[{_fmt(joint.q_min_deg)}, {_fmt(joint.q_max_deg)}] deg",
            )


def _test_set(r: _Reader) -> TestSetConfig:
    return TestSetConfig(count=r.integer("count", 50, lo=0), seed=r.integer("seed", 0, lo=0))


def _check_poses(r: _Reader) -> CheckPosesConfig:
    return CheckPosesConfig(
        count=r.integer("count", 0, lo=0),
        every_n_points=r.integer("every_n_points", 50, lo=1),
    )


def _calibration(r: _Reader) -> CalibrationConfig:
    k0 = r.number("k0", 1.5, positive=True)
    k1 = r.number("k1", 2.5, positive=True)
    if k1 <= k0:
        raise r.error("k1", f"expected a number > k0 = {_fmt(k0)}, got {_fmt(k1)}")
    return CalibrationConfig(
        method=r.choice("method", CALIBRATION_METHODS, "lm"),
        weights=r.choice("weights", WEIGHT_FUNCTIONS, "igg3"),
        k0=k0,
        k1=k1,
        ridge_mu=r.number("ridge_mu", 1e-6, lo=0.0),
        residual=r.choice("residual", RESIDUAL_MODELS, "auto"),
        idw_power=r.number("idw_power", 2.0, positive=True),
        idw_k_nearest=r.integer("idw_k_nearest", 8, lo=1),
        joints=r.choice("joints", JOINT_SETS, "auto"),
        outliers=r.choice("outliers", OUTLIER_SCREENS, "local"),
        effects=_model_effects(r),
        cv_folds=r.integer("cv_folds", 5, lo=2, hi=20),
    )


def _model_effects(r: _Reader) -> str | tuple[EffectSpec, ...]:
    """``calibration.effects``: ``auto`` | ``none`` | a list of effect specs of the robot model."""
    value = r.data.get("effects", "auto")
    if value is None or isinstance(value, str):
        return r.choice("effects", ("auto", "none"), "auto")
    specs = _effects(r)
    where = r.child_list("effects")
    for i, spec in enumerate(specs):
        if spec.name not in MODEL_EFFECT_NAMES:
            raise ConfigError(r.file, where.key_path(i) + ".name", f"effect {spec.name!r} is not a robot effect "
                              f"(expected one of: {', '.join(MODEL_EFFECT_NAMES)})")
        if spec.scale != 1.0:
            raise ConfigError(r.file, where.key_path(i) + ".scale", "scale applies to simulated effects only")
    return specs


def _correction(r: _Reader) -> CorrectionConfig:
    return CorrectionConfig(
        generator=r.choice("generator", CORRECTION_GENERATORS, "ensemble"),
        error=r.choice("error", ERROR_FUNCTIONS, "position"),
        threshold_mm=r.number("threshold_mm", 1e-4, positive=True),
        max_iterations=r.integer("max_iterations", 20, lo=1),
        max_joint_correction_deg=r.number("max_joint_correction_deg", 0.5, positive=True),
        max_position_correction_mm=r.number("max_position_correction_mm", 5.0, positive=True),
        closed_loop_iterations=r.integer("closed_loop_iterations", 2, lo=0),
        significance=r.number("significance", 3.0, lo=0.0),
    )


def _simulation(r: _Reader, tool: ToolConfig, tracker: TrackerConfig, n_joints: int = 6) -> SimulationConfig:
    matrix = r.matrix("T_tracker_base", 4, 4, _default_T_tracker_base(tracker.position_in_base_mm))
    _check_rigid(matrix, r.key_path("T_tracker_base"), r.file)
    return SimulationConfig(
        seed=r.integer("seed", 0, lo=0),
        geometric_error_scale=r.number("geometric_error_scale", 1.0, lo=0.0),
        T_tracker_base=matrix,
        p_flange_smr_mm=r.vector("p_flange_smr_mm", 3, list(tool.p_flange_smr_mm)),
        effects=_effects(r),
        motion_time_s=r.number("motion_time_s", 0.0, lo=0.0),
        faults=_faults(r.section("faults", FaultsConfig, required=False)),
        readback_lag_deg_per_deg=r.vector("readback_lag_deg_per_deg", n_joints, [0.0] * n_joints),
        readback_noise_deg=r.number("readback_noise_deg", 0.0, lo=0.0),
        tracker_drift_mm_per_h=r.vector("tracker_drift_mm_per_h", 3, [0.0, 0.0, 0.0]),
        tracker_drift_urad_per_h=r.vector("tracker_drift_urad_per_h", 3, [0.0, 0.0, 0.0]),
        tracker_drift_tau_s=r.number("tracker_drift_tau_s", 0.0, lo=0.0),
    )


def _default_T_tracker_base(position: Vec3 | None) -> list[list[float]]:
    """Pure translation putting the tracker at ``position`` (mm, base frame); identity if unknown."""
    x, y, z = position if position is not None else (0.0, 0.0, 0.0)
    return [[1.0, 0.0, 0.0, -x], [0.0, 1.0, 0.0, -y], [0.0, 0.0, 1.0, -z], [0.0, 0.0, 0.0, 1.0]]


def _check_rigid(m: Sequence[Sequence[float]], path: str, file: str) -> None:
    """Last row [0, 0, 0, 1]; rotation block orthonormal with det +1 (tolerance 1e-3)."""
    if any(abs(v - e) > 1e-9 for v, e in zip(m[3], (0.0, 0.0, 0.0, 1.0))):
        got = ", ".join(_fmt(v) for v in m[3])
        raise ConfigError(file, f"{path}[3]", f"expected the last row [0, 0, 0, 1], got [{got}]")
    cols = [[m[r][c] for r in range(3)] for c in range(3)]
    gram_err = max(
        abs(sum(a * b for a, b in zip(cols[i], cols[j])) - (1.0 if i == j else 0.0))
        for i in range(3)
        for j in range(3)
    )
    if gram_err > _ORTHONORMAL_TOL:
        raise ConfigError(file, path, f"rotation part is not orthonormal (max |R^T R - I| = {gram_err:.3g} > {_ORTHONORMAL_TOL:g})")
    det = _det3([row[:3] for row in m[:3]])
    if abs(det - 1.0) > _ORTHONORMAL_TOL:
        raise ConfigError(file, path, f"rotation part must have det +1 (a proper rotation), got {det:.6g}")


def _det3(a: Sequence[Sequence[float]]) -> float:
    """Determinant of a 3x3 matrix."""
    return (
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    )


def _effects(r: _Reader) -> tuple[EffectSpec, ...]:
    """``simulation.effects``: names or ``{name, scale, params}`` mappings, no duplicates."""
    where = r.child_list("effects")
    specs: list[EffectSpec] = []
    for i, item in enumerate(r.items("effects", [], what="effects")):
        spec = _effect(where.reader(i, {"name": item} if isinstance(item, str) else item, EffectSpec))
        if any(s.name == spec.name for s in specs):
            raise ConfigError(r.file, where.key_path(i) + ".name", f"duplicate effect {spec.name!r}")
        specs.append(spec)
    return tuple(specs)


def _effect(r: _Reader) -> EffectSpec:
    return EffectSpec(
        name=r.choice("name", EFFECT_NAMES),
        scale=r.number("scale", 1.0, lo=0.0),
        params=r.mapping("params", {}),
    )


def _faults(r: _Reader) -> FaultsConfig:
    def p(key: str) -> float:
        return r.number(key, 0.0, lo=0.0, hi=1.0)

    return FaultsConfig(
        beam_break_probability=p("beam_break_probability"),
        timeout_probability=p("timeout_probability"),
        garbage_probability=p("garbage_probability"),
    )


def _output(r: _Reader) -> OutputConfig:
    return OutputConfig(dir=r.string("dir", "runs"))
