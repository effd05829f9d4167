"""The campaign configuration schema: one frozen dataclass per YAML section (robot, tool, tracker, calibration,
correction, simulation, output) and the whole file (``CampaignConfig``). The plan section is in
:mod:`campaign.config.plan_schema`, the choice tables and shared value types in :mod:`campaign.config.values`.

Read by :mod:`campaign.config.load` and :mod:`campaign.config.sections`."""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

# tracker.uncertainty: robocal owns the class and its numerics; the YAML section requires the four MPE terms
# (micrometres, micrometres per metre) and takes coverage_k (default 2), see campaign.config.load._uncertainty
from robocal.measure.noise import TrackerUncertainty, noise_max_mm

from campaign.config.plan_schema import PlanConfig
from campaign.config.values import Matrix4, Vec3


@dataclass(frozen=True, slots=True)
class JointConfig:
    """One row of the DH (or MDH) table; lengths in mm, angles in degrees.

    ``theta_deg`` is the offset added to the controller's joint value
    (YAML default 0). ``q_min_deg < q_max_deg`` are the controller's axis limits.
    A linear track (``type: prismatic``, the first joint only; docs/chains.md): YAML keys ``axis`` (its direction in
    the robot base frame), ``q_min_mm``/``q_max_mm`` (travel) and ``mechanical_unit`` (the controller's name of the
    unit, e.g. an ABB ``TRACK_1``); its travel limits are held in ``q_min_deg``/``q_max_deg`` in mm (joint vectors
    carry the carriage position in mm where they carry angles in degrees) and its DH values are zero.
    """

    alpha_deg: float
    a_mm: float
    d_mm: float
    theta_deg: float
    q_min_deg: float
    q_max_deg: float
    type: str = "revolute"
    axis: Vec3 | None = None
    mechanical_unit: str | None = None

    def plain(self) -> dict[str, Any]:
        """The row as a config file writes it (a track with its own keys)."""
        if self.type == "prismatic":
            return {"type": "prismatic", "axis": list(self.axis or ()), "q_min_mm": self.q_min_deg,
                    "q_max_mm": self.q_max_deg, "mechanical_unit": self.mechanical_unit}
        return {k: getattr(self, k) for k in ("alpha_deg", "a_mm", "d_mm", "theta_deg", "q_min_deg", "q_max_deg")}


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """The robot arm and how to reach its controller.

    ``url`` scheme selects the driver (one of ``drivers.registry.ROBOT_SCHEMES``). ``model`` (required, e.g. "ABB IRB
    2600-12/1.65") is compared with the model the controller reports at connect (a different model stops the run
    before the first move; vendor formatting is tolerated).
    ``hayati_joints``: 1-based joints whose axis is parallel to the next one
    (default none). ``repeatability_mm`` (ISO 9283 RP, default 0.05) and
    ``max_joint_speed_deg_s`` (default 30) feed noise and duration estimates.
    ``options`` (default empty) are passed to the driver unchanged.
    Gravity model of the physical effects (``robocal.effects.bases.GravityModel``): ``link_masses_kg`` (one lumped mass
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

    @property
    def track(self) -> JointConfig | None:
        """The linear track (joint 1, ``type: prismatic``), None for an arm on a fixed base."""
        return self.joints[0] if self.joints and self.joints[0].type == "prismatic" else None


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

    ``url`` scheme selects the driver (one of ``drivers.registry.TRACKER_SCHEMES``).
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
class CalibrationConfig:
    """Identification settings (the whole section is optional).

    Defaults: ``method`` lm, ``weights`` igg3 (robust_ridge only), ``k0`` 1.5 < ``k1`` 2.5
    (IGG-III thresholds, in units of sigma), ``ridge_mu`` 1e-6 (>= 0),
    ``residual`` auto, ``idw_power`` 2.0 (> 0), ``idw_k_nearest`` 8 (int >= 1),
    ``outliers`` local, ``effects`` auto, ``cv_folds`` 5 (int >= 2).

    ``outliers``: ``local`` excludes a point only as a measurement fault (residual isolated against its
    neighbours in joint space and in the workspace, tracker statistics, repeats); ``none`` keeps all.
    ``effects``: ``auto`` (forward selection of physical effects by k-fold CV on the calibration points),
    ``none``, or a list of effect specs (``name`` in ``robocal.effects.bases.MODEL_EFFECTS``, optional ``params`` with the
    factory's keys: joints, joint, harmonics, tau_s, link_masses_kg) that become parameters of the model.
    ``residual`` ``auto`` chooses none / idw / gpr / joint_gp / trend_gpr by k-fold CV and keeps a layer only when it beats
    none by more than one standard error of the CV difference.

    ``residual`` (one of ``values.RESIDUAL_MODELS``) is the layer fitted on top of
    the kinematic model: ``idw`` inverse distance weighting over positions
    (seed 000), ``gpr`` Gaussian-process regression over joint angles, one
    model per base-frame axis (seed 003; the payload becomes an extra input
    when it varies across the calibration points; the report gives the
    predictive standard deviation of every test point), ``joint_gp`` one
    angle-error curve per joint (a GP over that joint's angle) moved to the
    SMR through the Jacobian (``robocal.layers.joint_gp``), ``trend_gpr`` a
    quadratic trend over the workspace (base frame) fitted with a linearised
    change of the identified geometry, and the GPR on what they leave
    (``robocal.layers.trend``; ``auto`` offers it up to 3000 calibration
    rows), ``none`` no layer.
    ``idw_*`` apply to ``idw`` only.

    ``joints`` (one of ``values.JOINT_SETS``, default auto) which joint values drive
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

    ``name`` in ``robocal.effects.bases.SIMULATED_EFFECTS``; ``scale`` >= 0 (default 1); ``params``
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

    def below_noise(self, floor_mm: float, n_test: int) -> tuple[str, ...]:
        """The bounds a perfect model fails more often than not on noise alone: ``max_rms_mm`` below the noise floor
        ``floor_mm`` (3-D RMS, mm), ``max_mm`` below the median largest of ``n_test`` noise-only errors
        (:func:`robocal.measure.noise.noise_max_mm`)."""
        rms = self.max_rms_mm is not None and self.max_rms_mm < floor_mm
        big = self.max_mm is not None and n_test > 0 and self.max_mm < noise_max_mm(floor_mm, n_test)
        return ("max_rms_mm",) * rms + ("max_mm",) * big


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
    if isinstance(value, JointConfig):
        return value.plain()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _to_plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_to_plain(v) for v in value]
    return value


