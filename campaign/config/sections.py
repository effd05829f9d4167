"""Readers of the plan, calibration, correction, simulation, output and acceptance sections of a config file."""
from __future__ import annotations

from collections.abc import Sequence
import math

from campaign.config.plan_section import optimal_keys
from campaign.config.reader import ListPath, Reader, describe, fmt
from campaign.config.plan_schema import (BoxConfig, CheckPosesConfig, GridConfig, Iso9283Config, NestConfig,
                                         NestsConfig, PlanConfig, TestSetConfig)
from campaign.config.schema import (AcceptanceConfig, CalibrationConfig, CorrectionConfig, EffectSpec, FaultsConfig,
                                    JointConfig, OutputConfig, RobotConfig, SimulationConfig, ToolConfig,
                                    TrackerConfig)
from campaign.config.values import (CALIBRATION_METHODS, CORRECTION_GENERATORS, ERROR_FUNCTIONS, JOINT_SETS,
                                    OUTLIER_SCREENS, PLAN_ORDERS, RESIDUAL_MODELS, Vec3, WEIGHT_FUNCTIONS, NAME_RE,
                                    ORTHONORMAL_TOL)
from campaign.errors import ConfigError
from robocal.effects.bases import SIMULATED_EFFECTS, MODEL_EFFECTS


def read_plan(r: Reader, robot: RobotConfig, tool: ToolConfig) -> PlanConfig:
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
        **_track_keys(r, robot),
    )


def _track_keys(r: Reader, robot: RobotConfig) -> dict:
    """``plan.track_stations`` of a robot on a track (grid plans only)."""
    if robot.track is None:
        if r.data.get("track_stations") is not None:                   # (None: written by to_dict)
            raise r.error("track_stations", "the robot has no track (robot.joints[0] with type: prismatic)")
        return {}
    if r.data.get("kind", "grid") != "grid":
        raise r.error("kind", "a robot on a track is planned as a grid (the carriage at track_stations stations); "
                              "optimal and iso9283 plans keep the carriage still")
    return {"track_stations": r.integer("track_stations", 5, lo=2, hi=1000)}


def _keep_out(r: Reader) -> tuple[BoxConfig, ...]:
    """``plan.keep_out``: a list of boxes ``{name, min_mm, max_mm}`` (base frame, mm)."""
    where = r.child_list("keep_out")
    return tuple(_box(where.reader(i, item, BoxConfig), f"keep_out[{i}]")
                 for i, item in enumerate(r.items("keep_out", [], what="boxes")))


def _box(r: Reader, default_name: str) -> BoxConfig:
    lo, hi = r.vector("min_mm", 3), r.vector("max_mm", 3)
    for k, axis in enumerate("xyz"):
        if hi[k] <= lo[k]:
            raise r.error("max_mm", f"expected max_mm.{axis} > min_mm.{axis} = {fmt(lo[k])}, got {fmt(hi[k])}")
    return BoxConfig(name=r.string("name", default_name), min_mm=lo, max_mm=hi)


def _nests(r: Reader) -> NestsConfig:
    """``plan.nests``: ids unique and non-empty, positions in the base frame (mm)."""
    where = r.child_list("points")
    points: list[NestConfig] = []
    for i, item in enumerate(r.items("points", [], what="nests")):
        nr = where.reader(i, item, NestConfig)
        nest = NestConfig(id=nr.string("id"), p_base_mm=nr.vector("p_base_mm", 3),
                          p_tracker_mm=nr.vector("p_tracker_mm", 3, None))
        if not NAME_RE.match(nest.id):
            raise nr.error("id", f"expected letters, digits, '_', '.' or '-', got {describe(nest.id)}")
        if any(n.id == nest.id for n in points):
            raise nr.error("id", f"duplicate nest id {nest.id!r}")
        points.append(nest)
    return NestsConfig(points=tuple(points), every_n_points=r.integer("every_n_points", 50, lo=1),
                       max_move_mm=r.number("max_move_mm", 0.2, positive=True))


def _iso9283(r: Reader) -> Iso9283Config:
    return Iso9283Config(cycles=r.integer("cycles", 30, lo=3), edge_mm=r.number("edge_mm", 0.0, lo=0.0))


def _grid(r: Reader) -> GridConfig:
    return GridConfig(
        center_mm=r.vector("center_mm", 3),
        size_mm=r.vector("size_mm", 3, positive=True),
        step_mm=r.number("step_mm", positive=True),
    )


def _check_reach(grid: GridConfig, robot: RobotConfig, tool: ToolConfig, plan: Reader) -> None:
    """Every box corner must lie within sum(|a| + |d|) + |p_flange_smr| of the base origin (mm)."""
    reach = sum(abs(j.a_mm) + abs(j.d_mm) for j in robot.joints) + math.hypot(*tool.p_flange_smr_mm)
    half = [s / 2 for s in grid.size_mm]
    corner = tuple(c + (h if c >= 0 else -h) for c, h in zip(grid.center_mm, half))  # farthest corner
    distance = math.hypot(*corner)
    if distance > reach:
        coords = ", ".join(fmt(c) for c in corner)
        raise ConfigError(
            plan.file,
            plan.key_path("grid") + ".center_mm",
            f"box corner ({coords}) mm is outside the robot's reach "
            f"(max {reach:.1f} mm, corner at {distance:.1f} mm)",
        )


def _check_q_ref(q_ref: Sequence[float], joints: Sequence[JointConfig], where: ListPath) -> None:
    """Each reference joint value must lie inside its joint's limits (deg; a track's in mm)."""
    for i, (q, joint) in enumerate(zip(q_ref, joints)):
        if not joint.q_min_deg <= q <= joint.q_max_deg:
            u = "mm" if joint.type == "prismatic" else "deg"
            raise where.error(
                i,
                f"{fmt(q)} {u} is outside joint {i + 1} limits "
                f"[{fmt(joint.q_min_deg)}, {fmt(joint.q_max_deg)}] {u}",
            )


def _test_set(r: Reader) -> TestSetConfig:
    return TestSetConfig(count=r.integer("count", 50, lo=0), seed=r.integer("seed", 0, lo=0))


def _check_poses(r: Reader) -> CheckPosesConfig:
    return CheckPosesConfig(
        count=r.integer("count", 0, lo=0),
        every_n_points=r.integer("every_n_points", 50, lo=1),
    )


def read_calibration(r: Reader) -> CalibrationConfig:
    k0 = r.number("k0", 1.5, positive=True)
    k1 = r.number("k1", 2.5, positive=True)
    if k1 <= k0:
        raise r.error("k1", f"expected a number > k0 = {fmt(k0)}, got {fmt(k1)}")
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


def _model_effects(r: Reader) -> str | tuple[EffectSpec, ...]:
    """``calibration.effects``: ``auto`` | ``none`` | a list of effect specs of the robot model."""
    value = r.data.get("effects", "auto")
    if value is None or isinstance(value, str):
        return r.choice("effects", ("auto", "none"), "auto")
    specs = _effects(r, MODEL_EFFECTS)
    where = r.child_list("effects")
    from robocal.effects.bases import FACTORY_KEYS, by_name

    for i, spec in enumerate(specs):
        for key in spec.params:
            if key not in FACTORY_KEYS[spec.name]:
                raise ConfigError(r.file, f"{where.key_path(i)}.params.{key}", f"unknown parameter of "
                                  f"{spec.name} (expected one of: {', '.join(sorted(FACTORY_KEYS[spec.name])) or 'none'})")
        if spec.scale != 1.0:
            raise ConfigError(r.file, where.key_path(i) + ".scale", "scale applies to simulated effects only")
        try:                                   # a value the factory refuses (a form, a joint list) fails here, not
            by_name(spec.name, **dict(spec.params))         # after the measurements
        except (ValueError, TypeError) as exc:
            raise ConfigError(r.file, f"{where.key_path(i)}.params", str(exc).splitlines()[0]) from None
    return specs


def read_correction(r: Reader) -> CorrectionConfig:
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


def read_simulation(r: Reader, tool: ToolConfig, tracker: TrackerConfig, n_joints: int = 6) -> SimulationConfig:
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
        got = ", ".join(fmt(v) for v in m[3])
        raise ConfigError(file, f"{path}[3]", f"expected the last row [0, 0, 0, 1], got [{got}]")
    cols = [[m[r][c] for r in range(3)] for c in range(3)]
    gram_err = max(
        abs(sum(a * b for a, b in zip(cols[i], cols[j])) - (1.0 if i == j else 0.0))
        for i in range(3)
        for j in range(3)
    )
    if gram_err > ORTHONORMAL_TOL:
        raise ConfigError(file, path, f"rotation part is not orthonormal (max |R^T R - I| = {gram_err:.3g} > {ORTHONORMAL_TOL:g})")
    det = _det3([row[:3] for row in m[:3]])
    if abs(det - 1.0) > ORTHONORMAL_TOL:
        raise ConfigError(file, path, f"rotation part must have det +1 (a proper rotation), got {det:.6g}")


def _det3(a: Sequence[Sequence[float]]) -> float:
    """Determinant of a 3x3 matrix."""
    return (
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    )


def _effects(r: Reader, names: tuple[str, ...] = SIMULATED_EFFECTS) -> tuple[EffectSpec, ...]:
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


def _effect(r: Reader, names: tuple[str, ...] = SIMULATED_EFFECTS) -> EffectSpec:
    return EffectSpec(
        name=r.choice("name", names),
        scale=r.number("scale", 1.0, lo=0.0),
        params=r.mapping("params", {}),
    )


def _faults(r: Reader) -> FaultsConfig:
    def p(key: str) -> float:
        return r.number(key, 0.0, lo=0.0, hi=1.0)

    return FaultsConfig(
        beam_break_probability=p("beam_break_probability"),
        timeout_probability=p("timeout_probability"),
        garbage_probability=p("garbage_probability"),
    )


def read_output(r: Reader) -> OutputConfig:
    return OutputConfig(dir=r.string("dir", "runs"))


def read_acceptance(r: Reader) -> AcceptanceConfig:
    """Each bound optional (absent or null: not checked)."""
    return AcceptanceConfig(*(None if r.data.get(k) is None else r.number(k, positive=True)
                              for k in ("max_rms_mm", "max_mm")))
