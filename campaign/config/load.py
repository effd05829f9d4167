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

from collections.abc import Iterable
import hashlib
import math
from pathlib import Path
from typing import Any

import yaml

from campaign.config.bounded_yaml import load_limited, read_limited
from campaign.config.reader import Reader, describe, fmt, field_keys
from campaign.config.plan_schema import PlanConfig
from campaign.config.schema import (AcceptanceConfig, CalibrationConfig, CampaignConfig, CorrectionConfig,
                                    JointConfig, MeasurementConfig, OutputConfig, RobotConfig, SimulationConfig,
                                    ToolConfig, TrackerConfig)
from campaign.config.values import CONVENTIONS, FILE_NAME_MAX, MAX_JOINTS, MAX_NAME_CHARS, NAME_RE
from campaign.errors import ConfigError
from drivers.registry import ROBOT_SCHEMES, TRACKER_SCHEMES
from robocal.measure.noise import TrackerUncertainty

from .cell_model import CellModel
from .checks import check_config, check_joint_count, check_numerics
from .sections import read_acceptance, read_calibration, read_correction, read_output, read_plan, read_simulation


__all__ = ["load_cell", "load_config", "parse_config"]


# --------------------------------------------------------------------------- loading


def load_cell(path: str | Path) -> CellModel:
    """The cell model of the campaign file at ``path``: :func:`load_config`, the model built once, and the checks
    that need it (Hayati joints, simulated effects). What every command starts from; ConfigError as load_config."""
    cell = CellModel.from_config(load_config(path))
    check_numerics(cell)
    return cell


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
        raise ConfigError(file, "", f"top level must be a mapping of sections, got {describe(doc)}")
    cfg = _campaign(Reader(doc, file, "", field_keys(CampaignConfig, "source_path", "sha256")),
                    sha256=hashlib.sha256(data).hexdigest())
    check_config(cfg)                                   # cross-key checks: sizes, drivers, effects
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


def _campaign(r: Reader, sha256: str) -> CampaignConfig:
    """Top level: sections in dependency order (robot -> tool -> tracker -> plan -> simulation)."""
    name = r.string("name")
    if not NAME_RE.match(name):
        raise r.error("name", f"expected letters, digits, '_', '.' or '-' (it names run directories), got {describe(name)}")
    if len(name) > MAX_NAME_CHARS:
        raise r.error("name", f"{len(name)} characters: at most {MAX_NAME_CHARS} (it names run directories, "
                              f"NAME-TIMESTAMP, and a file name holds {FILE_NAME_MAX} bytes)")
    robot = _robot(r.section("robot", RobotConfig))
    tool = _tool(r.section("tool", ToolConfig))
    tracker = _tracker(r.section("tracker", TrackerConfig))
    plan = read_plan(r.section("plan", PlanConfig), robot, tool)
    return CampaignConfig(
        name=name,
        robot=robot,
        tool=tool,
        tracker=tracker,
        plan=plan,
        calibration=read_calibration(r.section("calibration", CalibrationConfig, required=False)),
        correction=read_correction(r.section("correction", CorrectionConfig, required=False)),
        simulation=read_simulation(r.section("simulation", SimulationConfig, required=False), tool, tracker,
                               robot.n_joints),
        output=read_output(r.section("output", OutputConfig, required=False)),
        source_path=r.file,
        sha256=sha256,
        acceptance=read_acceptance(r.section("acceptance", AcceptanceConfig, required=False)),
    )


def _robot(r: Reader) -> RobotConfig:
    model = r.string("model")
    url = r.url("url", ROBOT_SCHEMES)
    convention = r.choice("convention", CONVENTIONS)
    rows = r.items("joints", min_len=1, max_len=MAX_JOINTS, what="joint mappings")
    where = r.child_list("joints")
    joints = tuple(_joint(Reader(row, r.file, where.key_path(i), TRACK_KEYS)) if _prismatic(row)
                   else _joint(where.reader(i, row, JointConfig)) for i, row in enumerate(rows))
    check_joint_count(joints, r.file)                   # before the plan's checks use the joints
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


def _gravity(r: Reader, n: int) -> dict[str, Any]:
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


def _motion_caps(r: Reader) -> dict[str, Any]:
    """Speed caps: the TCP cap must not exceed the datasheet maximum (mm/s) when one is given."""
    given = r.data.get("datasheet_max_tcp_speed_mm_s") is not None
    datasheet = r.number("datasheet_max_tcp_speed_mm_s", positive=True) if given else None
    tcp = r.number("max_tcp_speed_mm_s", 250.0, positive=True)
    if datasheet is not None and tcp > datasheet:
        raise r.error("max_tcp_speed_mm_s", f"{fmt(tcp)} mm/s exceeds the robot's datasheet maximum "
                                            f"datasheet_max_tcp_speed_mm_s = {fmt(datasheet)} mm/s")
    first = r.data.get("first_pass_speed_pct")
    return {"max_tcp_speed_mm_s": tcp, "datasheet_max_tcp_speed_mm_s": datasheet,
            "max_joint_speed_pct": r.number("max_joint_speed_pct", 100.0, positive=True, hi=100.0),
            "first_pass_speed_pct": None if first is None else r.number("first_pass_speed_pct", positive=True,
                                                                        hi=100.0)}


TRACK_KEYS = ("type", "axis", "q_min_mm", "q_max_mm", "mechanical_unit")


def _prismatic(row: Any) -> bool:
    return isinstance(row, dict) and row.get("type") == "prismatic"


def _joint(r: Reader) -> JointConfig:
    kind = r.choice("type", ("revolute", "prismatic"), "revolute")
    unit = "mm" if kind == "prismatic" else "deg"
    q_min = r.number(f"q_min_{unit}")
    q_max = r.number(f"q_max_{unit}")
    if q_min >= q_max:
        raise r.error(f"q_max_{unit}", f"expected a number > q_min_{unit} = {fmt(q_min)}, got {fmt(q_max)}")
    if kind == "prismatic":
        axis = r.vector("axis", 3)
        if math.hypot(*axis) < 1e-9:
            raise r.error("axis", "expected a non-zero direction")
        unit_name = r.data.get("mechanical_unit")
        return JointConfig(0.0, 0.0, 0.0, 0.0, q_min, q_max, "prismatic", tuple(axis),
                           None if unit_name is None else r.string("mechanical_unit"))
    return JointConfig(
        alpha_deg=r.number("alpha_deg"),
        a_mm=r.number("a_mm"),
        d_mm=r.number("d_mm"),
        theta_deg=r.number("theta_deg", 0.0),
        q_min_deg=q_min,
        q_max_deg=q_max,
    )


def _tool(r: Reader) -> ToolConfig:
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


def _check_smrs(tool: ToolConfig, r: Reader) -> None:
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
                                       f"(smr_diameter_mm = {fmt(tool.smr_diameter_mm)})")


def _tracker(r: Reader) -> TrackerConfig:
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


def _uncertainty(r: Reader) -> TrackerUncertainty:
    return TrackerUncertainty(
        transverse_a_um=r.number("transverse_a_um", positive=True),
        transverse_b_um_per_m=r.number("transverse_b_um_per_m", lo=0.0),
        range_a_um=r.number("range_a_um", positive=True),
        range_b_um_per_m=r.number("range_b_um_per_m", lo=0.0),
        coverage_k=r.number("coverage_k", 2.0, positive=True),
    )


def _measurement(r: Reader) -> MeasurementConfig:
    return MeasurementConfig(
        samples=r.integer("samples", 5, lo=1),
        stability_mm=r.number("stability_mm", 0.02, positive=True),
        settle_s=r.number("settle_s", 0.5, lo=0.0),
        timeout_s=r.number("timeout_s", 5.0, positive=True),
        retries=r.integer("retries", 3, lo=0),
        reading_time_s=r.number("reading_time_s", 1.5, positive=True),
    )
