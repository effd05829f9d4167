"""Safety bounds of corrected targets: the target records and :func:`check_targets`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral
from typing import Any, Iterable, Mapping, Sequence

# The writer tag in the header comment of every written file: kept as first published with the /1 formats (files on
# controllers carry it); it names the writer, not a module path.
GENERATOR = "campaign.writeback"
# /2: the predicted position error (and the solver tolerance, apart) replace /1's "predicted residual", which was
# the solver's convergence.
RAPID_FORMAT = "rapid-cal-targets/2"
URSCRIPT_FORMAT = "urscript-cal-targets/2"
UR_JSON_FORMAT = "ur-joint-targets/2"

JOINT_DECIMALS = 6        # deg
POSITION_DECIMALS = 4     # mm
QUAT_DECIMALS = 9         # quaternion components
ERROR_DECIMALS = 4        # mm (predicted errors in controller files)
UR_RAD_DECIMALS = 9       # rad in URScript
QUAT_UNIT_TOL = 1e-6      # |norm - 1| accepted by check_targets
UR_MAX_V_RAD_S = math.pi  # URScript joint speed bound (rad/s)
UR_MAX_A_RAD_S2 = 40.0    # URScript joint acceleration bound (rad/s^2)

# --------------------------------------------------------------------------
# data


@dataclass(frozen=True)
class CorrectedTarget:
    """One corrected target, as produced by target correction.

    ``q_nominal_deg`` / ``q_corrected_deg``: joints in degrees (nominal
    solution and corrected joints).  ``p_command_base_mm``: position (mm, robot
    base frame) to command so that the controller's nominal model reaches the
    corrected joints; ``quat_command_wxyz``: its orientation, unit quaternion
    (w, x, y, z) as ABB writes it; ``confdata``: ABB (cf1, cf4, cf6, cfx).
    ``solver_tolerance_mm``: the pseudo-target iteration's remaining distance
    between the model's pose and the target (mm; its convergence, not an
    accuracy); ``predicted_error_mm``: the position error the robot can expect
    (mm; :data:`campaign.correct.accuracy.PREDICTED_ERROR_METHOD`), nan when
    unknown; ``predicted_rot_err_deg``: predicted orientation error (deg), nan
    unless orientation was measured (three SMRs); ``predicted_std_mm``: 3-D
    predictive standard deviation of the residual layer at the corrected joints
    (GPR), nan when the model has none.
    ``arm_angle_deg``: a seven-axis arm's arm angle (robocal.kinematics.chains), nan otherwise.
    """

    target_id: str
    q_nominal_deg: tuple[float, ...]
    q_corrected_deg: tuple[float, ...]
    p_command_base_mm: tuple[float, float, float]
    quat_command_wxyz: tuple[float, float, float, float]
    confdata: tuple[int, int, int, int]
    solver_tolerance_mm: float
    predicted_error_mm: float = math.nan
    predicted_rot_err_deg: float = math.nan
    predicted_std_mm: float = math.nan
    arm_angle_deg: float = math.nan          # a seven-axis arm: the arm angle of the corrected joints (deg)


@dataclass(frozen=True)
class Rejected:
    """A target refused by :func:`check_targets`; ``reason`` is one line."""

    target_id: str
    reason: str


# --------------------------------------------------------------------------
# bounds


def _fmt(x: Any) -> str:
    """Short text of a number for messages (10 significant digits)."""
    try:
        return f"{float(x):.10g}"
    except (TypeError, ValueError):
        return repr(x)


def as_float(x: Any) -> float | None:
    """``float(x)`` for real numbers (not bool/str), else None."""
    if isinstance(x, (bool, str, bytes)):
        return None
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def _limits(q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Validated joint limits (deg) as float tuples; ValueError when unusable."""
    lo = tuple(as_float(v) for v in q_min_deg)
    hi = tuple(as_float(v) for v in q_max_deg)
    if not lo or len(lo) != len(hi):
        raise ValueError(f"joint limits: q_min_deg has {len(lo)} values, q_max_deg {len(hi)}")
    for j, (a, b) in enumerate(zip(lo, hi), 1):
        if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) or not a < b:
            raise ValueError(f"joint limits: j{j} needs finite q_min < q_max, got [{_fmt(a)}, {_fmt(b)}] deg")
    return lo, hi  # type: ignore[return-value]


def _bound(value: float | None, name: str) -> float | None:
    """A finite non-negative bound, or None; ValueError otherwise."""
    if value is None:
        return None
    v = as_float(value)
    if v is None or not math.isfinite(v) or v < 0:
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
    return v


def _id_problem(target_id: Any) -> str | None:
    """Why a target id cannot be written (None when fine)."""
    if not isinstance(target_id, str) or not target_id.strip():
        return f"target id must be non-empty text, got {target_id!r}"
    bad = [c for c in target_id if ord(c) < 32 or 127 <= ord(c) < 160]
    if bad:
        return f"target id {target_id!r} contains control character {bad[0]!r}"
    return None


def _vector_problems(values: Any, n: int, name: str) -> list[str]:
    """Length and finiteness problems of a numeric vector of n values."""
    try:
        vals = list(values)
    except TypeError:
        return [f"{name} must be a sequence of {n} numbers, got {values!r}"]
    if len(vals) != n:
        return [f"{name} has {len(vals)} values, expected {n}"]
    out = []
    for k, v in enumerate(vals):
        f = as_float(v)
        if f is None or not math.isfinite(f):
            out.append(f"non-finite {name}[{k}] = {v!r}")
    return out


def _shape_problems(t: CorrectedTarget, n: int) -> list[str]:
    """Sizes, finiteness and types of every field of ``t`` (n joints)."""
    out = []
    problem = _id_problem(t.target_id)
    if problem:
        out.append(problem)
    out += _vector_problems(t.q_corrected_deg, n, "q_corrected_deg")
    out += _vector_problems(t.q_nominal_deg, n, "q_nominal_deg")
    out += _vector_problems(t.p_command_base_mm, 3, "p_command_base_mm")
    out += _vector_problems(t.quat_command_wxyz, 4, "quat_command_wxyz")
    res = as_float(t.solver_tolerance_mm)
    if res is None or not math.isfinite(res) or res < 0:
        out.append(f"solver_tolerance_mm must be finite and >= 0, got {t.solver_tolerance_mm!r}")
    for name in ("predicted_error_mm", "predicted_rot_err_deg", "predicted_std_mm"):
        v = as_float(getattr(t, name))
        if v is None or math.isinf(v) or v < 0:
            out.append(f"{name} must be nan or finite >= 0, got {getattr(t, name)!r}")
    conf = tuple(t.confdata) if isinstance(t.confdata, (tuple, list)) else ()
    if len(conf) != 4 or not all(isinstance(c, Integral) and not isinstance(c, bool) for c in conf):
        out.append(f"confdata must be 4 integers (cf1, cf4, cf6, cfx), got {t.confdata!r}")
    return out


def _target_problems(t: CorrectedTarget, lo: Sequence[float], hi: Sequence[float]) -> list[str]:
    """Every problem a writer must refuse: shapes, non-finite values, joint limits (deg), quaternion."""
    if not isinstance(t, CorrectedTarget):
        return [f"expected a CorrectedTarget, got {type(t).__name__}"]
    out = _shape_problems(t, len(lo))
    if any("q_corrected_deg" in p for p in out):
        return out
    for j, (q, a, b) in enumerate(zip(t.q_corrected_deg, lo, hi), 1):
        if not a <= float(q) <= b:
            out.append(f"j{j} corrected {_fmt(q)} deg outside limits [{_fmt(a)}, {_fmt(b)}] deg")
    if not any("quat_command_wxyz" in p for p in out):
        norm = math.sqrt(sum(float(c) ** 2 for c in t.quat_command_wxyz))
        if abs(norm - 1.0) > QUAT_UNIT_TOL:
            out.append(f"quat_command_wxyz norm {_fmt(norm)} is not 1")
    return out


def _correction_problems(t: CorrectedTarget, max_joint_deg: float) -> list[str]:
    """Joints whose |q_corrected - q_nominal| (deg) exceeds ``max_joint_deg``."""
    out = []
    for j, (qn, qc) in enumerate(zip(t.q_nominal_deg, t.q_corrected_deg), 1):
        d = abs(float(qc) - float(qn))
        if d > max_joint_deg:
            out.append(f"j{j} correction |{_fmt(qc)} - {_fmt(qn)}| = {_fmt(d)} deg "
                       f"exceeds {_fmt(max_joint_deg)} deg")
    return out


def _position_problems(t: CorrectedTarget, max_mm: float,
                       p_target_base_mm: Mapping[str, Sequence[float]]) -> list[str]:
    """Distance (mm) of the command position from the target position above ``max_mm``."""
    p_target = p_target_base_mm.get(t.target_id)
    if p_target is None:
        return ["no target position given to check the position correction"]
    bad = _vector_problems(p_target, 3, "target position")
    if bad:
        return bad
    d = math.dist([float(v) for v in t.p_command_base_mm], [float(v) for v in p_target])
    if d > max_mm:
        return [f"command position moved {_fmt(d)} mm from the target (bound {_fmt(max_mm)} mm)"]
    return []


def check_targets(targets: Iterable[CorrectedTarget], q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                  max_joint_correction_deg: float, max_position_correction_mm: float | None = None,
                  p_target_base_mm: Mapping[str, Sequence[float]] | None = None,
                  ) -> tuple[list[CorrectedTarget], list[Rejected]]:
    """Split targets into (accepted, rejected), both in input order.

    A target is rejected, with a one-line reason naming the joint and the
    values, when: a field is non-finite or malformed (the predicted errors and
    std may be nan); a corrected joint (deg) leaves ``[q_min_deg, q_max_deg]``;
    ``|q_corrected - q_nominal|`` on a joint exceeds ``max_joint_correction_deg``
    (deg); the command position is more than ``max_position_correction_mm`` (mm)
    from ``p_target_base_mm[target_id]`` (mm, base frame); the quaternion is not
    unit; or its id repeats an earlier one.  Bad arguments raise ValueError.
    """
    lo, hi = _limits(q_min_deg, q_max_deg)
    max_joint = _bound(max_joint_correction_deg, "max_joint_correction_deg")
    if max_joint is None:
        raise ValueError("max_joint_correction_deg: expected a finite number >= 0, got None")
    max_pos = _bound(max_position_correction_mm, "max_position_correction_mm")
    if max_pos is not None and p_target_base_mm is None:
        raise ValueError("max_position_correction_mm needs p_target_base_mm (target id -> xyz mm)")
    accepted: list[CorrectedTarget] = []
    rejected: list[Rejected] = []
    seen: set[str] = set()
    for t in targets:
        problems = _target_problems(t, lo, hi)
        tid = getattr(t, "target_id", "")
        if not problems:
            problems += _correction_problems(t, max_joint)
            if max_pos is not None:
                problems += _position_problems(t, max_pos, p_target_base_mm or {})
        if isinstance(tid, str) and tid in seen:
            problems.insert(0, "duplicate target id")
        seen.add(tid if isinstance(tid, str) else repr(tid))
        if problems:
            rejected.append(Rejected(str(tid), " ".join("; ".join(problems).split())))
        else:
            accepted.append(t)
    return accepted, rejected


def require_writable(targets: Iterable[CorrectedTarget], q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                      *, n_joints: int | None = None, allow_empty: bool = True) -> list[CorrectedTarget]:
    """The writers' re-check: targets as a list, or ValueError naming every invalid target."""
    items = list(targets)
    lo, hi = _limits(q_min_deg, q_max_deg)
    if n_joints is not None and len(lo) != n_joints:
        raise ValueError(f"this format needs {n_joints} joints, the limits have {len(lo)}")
    if not items and not allow_empty:
        raise ValueError("no targets to write")
    errors, seen = [], set()
    for t in items:
        problems = _target_problems(t, lo, hi)
        tid = getattr(t, "target_id", None)
        if isinstance(tid, str) and tid in seen:
            problems.insert(0, "duplicate target id")
        seen.add(tid if isinstance(tid, str) else repr(tid))
        if problems:
            errors.append(f"{tid!r}: {'; '.join(problems)}")
    if errors:
        more = f" (and {len(errors) - 5} more)" if len(errors) > 5 else ""
        raise ValueError(f"refusing to write {len(errors)} invalid target(s): {' | '.join(errors[:5])}{more}")
    return items
