"""Whole-config checks run by ``load_config`` after the per-key schema, so that what ``validate`` accepts ``run``
accepts: joint count, sizes that allocate or loop, Hayati joints, every driver's url and options (through the
driver registry, no connection), and the simulated effects' parameters.

Every failure is a :class:`campaign.errors.ConfigError` with the file and the key path.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError

SUPPORTED_JOINTS = 6            # plan (wrist singularity), IK branch, ABB confdata and UR write-back are 6R
MAX_PLAN_POINTS = 20_000        # grid + test + check repeats: a real campaign has a few hundred
MAX_GRID_POINTS = 10_000
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
    _check_sizes(cfg, file)
    _check_hayati(cfg, file)
    _check_drivers(cfg, file)
    _check_effects(cfg)


def _check_joint_count(cfg, file: str) -> None:
    check_joint_count(cfg.robot.n_joints, file)


def check_joint_count(n: int, file: str) -> None:
    """The campaign commands support 6-joint arms only (ConfigError at robot.joints otherwise)."""
    if n != SUPPORTED_JOINTS:
        raise ConfigError(file, "robot.joints", f"the campaign supports 6-joint arms (plan, IK branch and "
                                                f"controller write-back are 6R), got {n} joints")


def grid_counts(cfg) -> tuple[int, int, int]:
    """Grid vertices per axis, as ``campaign.plan.grid_points`` makes them (capped to avoid overflow)."""
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
    bounds = [
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


def _check_hayati(cfg, file: str) -> None:
    """Hayati beta only on a joint whose axis is parallel to the next joint's axis (never the last joint)."""
    if not cfg.robot.hayati_joints:
        return
    from robocal.kinematics import chain

    from .cell import nominal_kinematics

    n = cfg.robot.n_joints
    kin = nominal_kinematics(cfg)
    axes = chain(kin, np.radians(np.asarray(cfg.plan.q_ref_deg, float))[None]).axis[0]    # (n, 3) base frame
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
        problem = check_options(kind, url, options, n_joints=cfg.robot.n_joints)
        if problem is not None:
            where, _, message = problem.partition(": ")
            raise ConfigError(file, f"{section}.{where}", message)


def _check_effects(cfg) -> None:
    """Effect names, params and values build (the run would build them the same way)."""
    from .cell import simulated_effects

    effects = simulated_effects(cfg, cfg.robot.n_joints)
    if not effects:
        return
    from robocal.effects import apply_effects
    from robocal.kinematics import smr_tracker

    from .cell import nominal_kinematics

    kin = nominal_kinematics(cfg)
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
