"""The measurement plan as data (``points``: plan points, sets, hash, plan.csv) and how it is built from a config
(``build``: ``build_plan`` and the grid plan; ``poses``: targets, their joints and skip reasons, check poses, nest
rounds, shared by every plan kind; ``optimal``: poses chosen from a candidate pool; ``iso9283``: the ISO 9283 cube
and its cycles), with the motion safety of every move (``motion_safety``: keep-out boxes, envelope along the swept
path, via poses, speed caps). Imports config, robocal and ``drivers.base``."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "acceptance": ("acceptance_warnings",),
    "adaptive": ("RULE", "SEED_DESIGN", "SEED_SIZE", "covered_task", "seed_rows", "seed_size", "task_poses"),
    "build": ("build_plan",),
    "iso9283": ("IsoCube", "is_iso_plan", "iso_cube", "iso_plan"),
    "learning": ("SIZES", "forecast_curve"),
    "motion_safety": ("PathGuard", "UnsafeMotion", "motion_limits", "payload"),
    "optimal": ("plan_forecast", "pose_covariance", "tracker_kinematics"),
    "points": ("CANDIDATE", "Plan", "PlanPoint", "plan_csv_text", "write_plan_csv"),
    "poses": ("tool_rotation", "unreachable_reasons", "with_nest_rounds"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
