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

from campaign.config_schema import *  # noqa: F401,F403  (the schema; re-exported)
from campaign.config_schema import (_NAME_RE, _ORTHONORMAL_TOL, FILE_NAME_MAX, MAX_NAME_CHARS,  # noqa: F401
                                    _to_plain)
from campaign.config_reader import *  # noqa: F401,F403
from campaign.config_plan import optimal_keys
from campaign.config_reader import (_REQUIRED, _ListPath, _Reader, _check_integer, _check_number,  # noqa: F401
                                    _check_vector, _describe, _fmt, _freeze, _keys)

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
    "PoolConfig",
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


# --------------------------------------------------------------------------- sections


def _campaign(r: _Reader, sha256: str) -> CampaignConfig:
    """Top level: sections in dependency order (robot -> tool -> tracker -> plan -> simulation)."""
    name = r.string("name")
    if not _NAME_RE.match(name):
        raise r.error("name", f"expected letters, digits, '_', '.' or '-' (it names run directories), got {_describe(name)}")
    if len(name) > MAX_NAME_CHARS:
        raise r.error("name", f"{len(name)} characters: at most {MAX_NAME_CHARS} (it names run directories, "
                              f"NAME-TIMESTAMP, and a file name holds {FILE_NAME_MAX} bytes)")
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
        **_gravity(r, len(joints)),
    )


def _gravity(r: _Reader, n: int) -> dict[str, Any]:
    """Link masses (kg, >= 0), the arm's mass (kg) and the direction of gravity in the base frame (non-zero)."""
    masses = r.vector("link_masses_kg", n, None)
    if masses is not None and any(m < 0 for m in masses):
        raise r.error("link_masses_kg", "masses must be >= 0 kg")
    mass = r.data.get("mass_kg")
    g = r.vector("gravity_direction_base", 3, [0.0, 0.0, -1.0])
    if sum(v * v for v in g) < 1e-12:
        raise r.error("gravity_direction_base", "expected a non-zero direction")
    return {"link_masses_kg": masses, "mass_kg": None if mass is None else r.number("mass_kg", positive=True),
            "gravity_direction_base": g}


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
        max_range_mm=None if r.data.get("max_range_mm") is None else r.number("max_range_mm", positive=True),
        max_incidence_deg=r.number("max_incidence_deg", 30.0, positive=True, hi=90.0),
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
        iso9283=_iso9283(r.section("iso9283", Iso9283Config, required=False)),
        **optimal_keys(r),
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
    specs = _effects(r, MODEL_EFFECT_NAMES)
    where = r.child_list("effects")
    from robocal.effects import FACTORY_KEYS

    for i, spec in enumerate(specs):
        for key in spec.params:
            if key not in FACTORY_KEYS[spec.name]:
                raise ConfigError(r.file, f"{where.key_path(i)}.params.{key}", f"unknown parameter of "
                                  f"{spec.name} (expected one of: {', '.join(sorted(FACTORY_KEYS[spec.name])) or 'none'})")
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


def _effects(r: _Reader, names: tuple[str, ...] = EFFECT_NAMES) -> tuple[EffectSpec, ...]:
    """``simulation.effects`` (or ``calibration.effects`` with ``names``): names or ``{name, scale, params}``
    mappings, no duplicates (the same name twice needs other params, e.g. gear_cyclic on two joints)."""
    where = r.child_list("effects")
    specs: list[EffectSpec] = []
    for i, item in enumerate(r.items("effects", [], what="effects")):
        spec = _effect(where.reader(i, {"name": item} if isinstance(item, str) else item, EffectSpec), names)
        if any(s.name == spec.name and dict(s.params) == dict(spec.params) for s in specs):
            raise ConfigError(r.file, where.key_path(i) + ".name", f"duplicate effect {spec.name!r}")
        specs.append(spec)
    return tuple(specs)


def _effect(r: _Reader, names: tuple[str, ...] = EFFECT_NAMES) -> EffectSpec:
    return EffectSpec(
        name=r.choice("name", names),
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
