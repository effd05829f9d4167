"""Whole-config checks, so that what ``validate`` accepts ``run`` accepts. ``check_config`` (run by ``load_config``
after the per-key schema): joint count, magnitudes, sizes that allocate or loop, every driver's url and options
(through the driver registry, no connection) and the simulated effects' parameters. ``check_numerics`` (run by
``load_cell`` on the built :class:`campaign.config.cell_model.CellModel`): Hayati joints and the simulated
effects' size at ``plan.q_ref_deg``, which need the nominal model.

Every failure is a :class:`campaign.errors.ConfigError` with the file and the key path.
"""
from __future__ import annotations

import math

import numpy as np

from campaign.errors import ConfigError

from .cell_model import CellModel
from .simulation import simulated_effects

SUPPORTED_JOINTS = (4, 7)       # revolute arms of 4 to 7 joints (docs/chains.md: what else is refused and why)
MAX_PLAN_POINTS = 20_000        # grid + test + check repeats: a real campaign has a few hundred
MAX_GRID_POINTS = 10_000
MAX_POOL_CELLS = 20_000         # candidate positions of an optimal plan (x orientations x branches)
MAX_TEST_POINTS = 10_000
MAX_CHECK_POSES = 100
MAX_SAMPLES = 1_000             # tracker readings averaged per point
MAX_RETRIES = 100
MAX_SECONDS = 3_600.0           # any single wait (settle, timeout, simulated move)
MAX_ITERATIONS = 10_000         # pseudo-target iterations
MAX_CLOSED_LOOP = 20
MAX_IDW_NEIGHBOURS = 10_000
MAX_EFFECT_MM = 50.0            # a simulated non-geometric effect larger than this is a typo, not a robot
PARALLEL_TOL_DEG = 1.0          # Hayati beta: axis i within this of axis i+1


def check_config(cfg) -> None:
    """Raise ConfigError for the first cross-key problem of a parsed ``CampaignConfig``."""
    file = cfg.source_path
    _check_joint_count(cfg, file)
    _check_magnitudes(cfg, file)
    _check_sizes(cfg, file)
    _check_drivers(cfg, file)
    simulated_effects(cfg, cfg.robot.n_joints)          # names, params and values build


def check_numerics(cell: CellModel) -> None:
    """Raise ConfigError for the first problem that needs the nominal model of a checked config."""
    _check_hayati(cell)
    _check_effects(cell)


def _check_joint_count(cfg, file: str) -> None:
    check_joint_count(cfg.robot.joints, file)


def check_joint_count(joints, file: str) -> None:
    """The campaign commands support arms of 4 to 7 revolute joints, on a fixed base or carried by a linear track
    (a prismatic first joint); ConfigError at robot.joints otherwise."""
    for k, j in enumerate(joints):
        if j.type == "prismatic" and k > 0:
            raise ConfigError(file, f"robot.joints[{k}].type", "a prismatic joint is supported as the first joint "
                                                               "only: a linear track carrying the arm")
    n = len(joints) - (1 if joints and joints[0].type == "prismatic" else 0)
    lo, hi = SUPPORTED_JOINTS
    if not lo <= n <= hi:
        raise ConfigError(file, "robot.joints", f"the campaign supports arms of {lo} to {hi} joints (fewer cannot "
                                                f"place and orient an SMR; more have no IK redundancy rule here), "
                                                f"got {n} revolute joints")


def grid_counts(cfg) -> tuple[int, int, int]:
    """Grid vertices per axis, as ``campaign.plan.poses.grid_points`` makes them (capped to avoid overflow)."""
    g = cfg.plan.grid
    return tuple(int(min(math.floor(s / g.step_mm + 1e-9), 1e9)) + 1 for s in g.size_mm)


def _check_sizes(cfg, file: str) -> None:
    """Bound every size that allocates memory or sets a loop count."""
    pl, m, c = cfg.plan, cfg.tracker.measurement, cfg.correction
    nx, ny, nz = grid_counts(cfg)
    n_grid = nx * ny * nz
    if n_grid > MAX_GRID_POINTS:
        raise ConfigError(file, "plan.grid.step_mm", f"{cfg.plan.grid.step_mm:g} mm makes {nx} x {ny} x {nz} = "
                                                      f"{n_grid} grid points (max {MAX_GRID_POINTS}): use a larger step")
    if pl.kind in ("optimal", "adaptive"):
        step = pl.pool.step_mm or pl.grid.step_mm / 2
        cells = math.prod(int(min(math.floor(s / step + 1e-9), 1e9)) + 1 for s in pl.grid.size_mm)
        if cells > MAX_POOL_CELLS:
            raise ConfigError(file, "plan.pool.step_mm", f"{step:g} mm makes {cells} candidate positions "
                                                         f"(max {MAX_POOL_CELLS}): use a larger step")
    bounds = [
        ("plan.points", pl.points or 0, MAX_GRID_POINTS),
        ("plan.max_points", pl.max_points or 0, MAX_GRID_POINTS),
        ("plan.test.count", pl.test.count, MAX_TEST_POINTS),
        ("plan.check_poses.count", pl.check_poses.count, MAX_CHECK_POSES),
        ("tracker.measurement.samples", m.samples, MAX_SAMPLES),
        ("tracker.measurement.retries", m.retries, MAX_RETRIES),
        ("tracker.measurement.settle_s", m.settle_s, MAX_SECONDS),
        ("tracker.measurement.timeout_s", m.timeout_s, MAX_SECONDS),
        ("simulation.motion_time_s", cfg.simulation.motion_time_s, MAX_SECONDS),
        ("correction.max_iterations", c.max_iterations, MAX_ITERATIONS),
        ("correction.closed_loop_iterations", c.closed_loop_iterations, MAX_CLOSED_LOOP),
        ("calibration.idw_k_nearest", cfg.calibration.idw_k_nearest, MAX_IDW_NEIGHBOURS),
    ]
    for key, value, limit in bounds:
        if value > limit:
            raise ConfigError(file, key, f"expected at most {limit:g}, got {value:g}")
    n_main = n_grid + pl.test.count
    repeats = (n_main // pl.check_poses.every_n_points + 2) if pl.check_poses.count else 0
    total = n_main + repeats * pl.check_poses.count
    if total > MAX_PLAN_POINTS:
        raise ConfigError(file, "plan.check_poses.every_n_points",
                          f"the plan would hold up to {total} points with the check-pose repeats "
                          f"(max {MAX_PLAN_POINTS}): repeat less often")


MAX_LENGTH_MM = 20_000.0        # any length, offset or position in the cell (a 20 m cell is already huge)
MAX_ANGLE_DEG = 10_000.0        # joint limits and offsets (multi-turn axes stay far below)


def _magnitudes(cfg) -> list[tuple[str, float, float]]:
    """(key path, value, largest plausible |value|) of every physical number that feeds a computation."""
    out: list[tuple[str, float, float]] = []
    for i, j in enumerate(cfg.robot.joints):
        if j.type == "prismatic":
            out += [(f"robot.joints[{i}].q_{e}_mm", getattr(j, f"q_{e}_deg"), MAX_LENGTH_MM) for e in ("min", "max")]
            continue
        for key in ("a_mm", "d_mm"):
            out.append((f"robot.joints[{i}].{key}", getattr(j, key), MAX_LENGTH_MM))
        for key in ("alpha_deg", "theta_deg", "q_min_deg", "q_max_deg"):
            out.append((f"robot.joints[{i}].{key}", getattr(j, key), MAX_ANGLE_DEG))
    vectors = [("tool.p_flange_smr_mm", cfg.tool.p_flange_smr_mm), ("tool.p_flange_smr2_mm", cfg.tool.p_flange_smr2_mm),
               ("tool.p_flange_smr3_mm", cfg.tool.p_flange_smr3_mm),
               ("tracker.position_in_base_mm", cfg.tracker.position_in_base_mm),
               ("simulation.p_flange_smr_mm", cfg.simulation.p_flange_smr_mm),
               ("plan.tool_direction", cfg.plan.tool_direction), ("plan.grid.center_mm", cfg.plan.grid.center_mm),
               ("plan.grid.size_mm", cfg.plan.grid.size_mm)]
    for key, vec in vectors:
        for k, v in enumerate(vec or ()):
            out.append((f"{key}[{k}]", v, MAX_LENGTH_MM))
    for r in range(3):
        out.append((f"simulation.T_tracker_base[{r}][3]", cfg.simulation.T_tracker_base[r][3], 10 * MAX_LENGTH_MM))
    u = cfg.tracker.uncertainty
    out += [("robot.repeatability_mm", cfg.robot.repeatability_mm, 10.0),
            ("robot.max_joint_speed_deg_s", cfg.robot.max_joint_speed_deg_s, 10_000.0),
            ("tool.smr_diameter_mm", cfg.tool.smr_diameter_mm, 1_000.0),
            ("tool.payload_kg", cfg.tool.payload_kg, 10_000.0),
            ("tracker.uncertainty.transverse_a_um", u.transverse_a_um, 100_000.0),
            ("tracker.uncertainty.transverse_b_um_per_m", u.transverse_b_um_per_m, 100_000.0),
            ("tracker.uncertainty.range_a_um", u.range_a_um, 100_000.0),
            ("tracker.uncertainty.range_b_um_per_m", u.range_b_um_per_m, 100_000.0),
            ("tracker.uncertainty.coverage_k", u.coverage_k, 100.0),
            ("tracker.measurement.stability_mm", cfg.tracker.measurement.stability_mm, 1_000.0),
            ("simulation.geometric_error_scale", cfg.simulation.geometric_error_scale, 100.0),
            ("calibration.ridge_mu", cfg.calibration.ridge_mu, 1e6),
            ("calibration.k1", cfg.calibration.k1, 1e3),
            ("calibration.idw_power", cfg.calibration.idw_power, 100.0),
            ("correction.threshold_mm", cfg.correction.threshold_mm, 1_000.0),
            ("correction.max_joint_correction_deg", cfg.correction.max_joint_correction_deg, 360.0),
            ("correction.max_position_correction_mm", cfg.correction.max_position_correction_mm, MAX_LENGTH_MM),
            ("correction.significance", cfg.correction.significance, 1e3)]
    smr_shift = max(abs(a - b) for a, b in zip(cfg.simulation.p_flange_smr_mm, cfg.tool.p_flange_smr_mm))
    out.append(("simulation.p_flange_smr_mm", smr_shift, 100.0))
    out.append(("plan.grid.step_mm", cfg.plan.grid.step_mm, MAX_LENGTH_MM))      # true vs nominal SMR: a few mm, not metres
    return out


def _check_magnitudes(cfg, file: str) -> None:
    """Every physical number within a plausible magnitude (1e300 mm passes 'finite' and overflows later)."""
    for key, value, limit in _magnitudes(cfg):
        if abs(value) > limit:
            what = "differs from tool.p_flange_smr_mm by" if key == "simulation.p_flange_smr_mm" else "is"
            raise ConfigError(file, key, f"{what} {value:.6g}: expected at most {limit:g} in magnitude")


def _check_hayati(cell: CellModel) -> None:
    """Hayati beta only on a joint whose axis is parallel to the next joint's axis (never the last joint)."""
    cfg, file = cell.config, cell.config.source_path
    if not cfg.robot.hayati_joints:
        return
    from robocal.kinematics.models import chain

    n = cfg.robot.n_joints
    axes = chain(cell.kinematics, np.radians(np.asarray(cfg.plan.q_ref_deg, float))[None]).axis[0]    # (n, 3) base frame
    for k, j in enumerate(cfg.robot.hayati_joints):
        where = f"robot.hayati_joints[{k}]"
        if j >= n:
            raise ConfigError(file, where, f"joint {j} is the last joint: Hayati beta needs a next joint parallel "
                                           "to it")
        a, b = axes[j - 1], axes[j]
        angle = math.degrees(math.asin(min(1.0, float(np.linalg.norm(np.cross(a, b))))))
        if angle > PARALLEL_TOL_DEG:
            raise ConfigError(file, where, f"the axes of joints {j} and {j + 1} are {angle:.1f} deg apart, not "
                                           "parallel: Hayati beta is only for parallel consecutive axes")


def _check_drivers(cfg, file: str) -> None:
    """Robot and tracker url + options, checked by the drivers themselves through the registry."""
    from drivers.registry import check_options

    tracker_options = {"timeout_s": cfg.tracker.measurement.timeout_s, **cfg.tracker.options}  # as the run does
    for section, kind, url, options in (("robot", "robot", cfg.robot.url, cfg.robot.options),
                                        ("tracker", "tracker", cfg.tracker.url, tracker_options)):
        track = cfg.robot.track.mechanical_unit if cfg.robot.track is not None else None
        problem = check_options(kind, url, options, n_joints=cfg.robot.n_joints,
                                **({"track_unit": track} if track and kind == "robot" else {}))
        if problem is not None:
            where, _, message = problem.partition(": ")
            raise ConfigError(file, f"{section}.{where}", message)


def _check_effects(cell: CellModel) -> None:
    """Each simulated effect evaluates to a finite shift of the SMR below MAX_EFFECT_MM at ``plan.q_ref_deg`` (the
    run would build them the same way)."""
    cfg, kin = cell.config, cell.kinematics
    effects = simulated_effects(cfg, cfg.robot.n_joints)
    if not effects:
        return
    from robocal.effects.bases import apply_effects
    from robocal.kinematics.models import smr_tracker

    q = np.radians(np.asarray(cfg.plan.q_ref_deg, float))[None]
    meta = {"t_s": np.array([3600.0]), "temp_c": np.array([25.0]), "payload_kg": np.array([cfg.tool.payload_kg])}
    for i, (eff, params) in enumerate(effects):
        where = f"simulation.effects[{i}]"
        if not np.all(np.isfinite(params)):
            raise ConfigError(cfg.source_path, f"{where}.params", "non-finite effect parameters")
        try:
            with np.errstate(all="ignore"):
                moved = apply_effects(kin, q, meta, ((eff, params),)) - smr_tracker(kin, q)
        except (ValueError, IndexError, KeyError, TypeError, ZeroDivisionError) as exc:
            raise ConfigError(cfg.source_path, f"{where}.params",
                              f"effect {eff.name!r} cannot be evaluated: {exc}") from None
        shift = float(np.max(np.linalg.norm(moved, axis=1)))
        if not np.isfinite(shift) or shift > MAX_EFFECT_MM:
            raise ConfigError(cfg.source_path, where, f"effect {eff.name!r} moves the SMR by {shift:.3g} mm at "
                                                      f"q_ref_deg (max {MAX_EFFECT_MM:g} mm): not a robot error")
