"""Write-back of corrected targets to robot controllers, behind safety bounds.

After calibration, target correction (``robocal.correct``) gives for each target
its nominal joints, corrected joints, the Cartesian command that reaches the
corrected joints with the controller's own nominal model, and the predicted
residual error.  This module

* checks the corrected targets against safety bounds (:func:`check_targets`):
  joint limits, the size of the joint correction, the size of the Cartesian
  correction and finiteness; a rejected target is reported, never written;
* writes the accepted targets for controllers and people:
  an ABB RAPID module (:func:`write_rapid_module`), Universal Robots JSON
  (:func:`write_ur_json`) and URScript (:func:`write_urscript`), and CSV
  (:func:`write_targets_csv`, :func:`write_rejected_csv`);
* checks RAPID and URScript text (:func:`check_rapid_syntax`,
  :func:`check_urscript_syntax`) and reads RAPID data back
  (:func:`parse_rapid_module`), so every written file is verified.

Defence in depth: every target writer takes the joint limits again
(``q_min_deg``/``q_max_deg``) and raises :class:`ValueError`, writing nothing,
when a target breaks them or is otherwise invalid.  Every writer writes
atomically (temporary file, fsync, ``os.replace``, directory fsync) and its
output is a pure function of its arguments (no dates), so writing twice gives
identical bytes.

Units: joints in degrees (``*_deg``) or radians (``*_rad``), positions and
residuals in mm, quaternions unit (w, x, y, z).  See ``docs/writeback.md``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass
from numbers import Integral
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .fsutil import atomic_write

__all__ = [
    "CorrectedTarget", "Rejected", "RapidExpr", "check_targets",
    "render_rapid_module", "write_rapid_module", "check_rapid_syntax", "parse_rapid_module",
    "render_ur_json", "write_ur_json", "render_urscript", "write_urscript", "check_urscript_syntax",
    "render_targets_csv", "write_targets_csv", "read_targets_csv", "write_rejected_csv",
]

GENERATOR = "campaign.writeback"
RAPID_FORMAT = "rapid-cal-targets/1"
URSCRIPT_FORMAT = "urscript-cal-targets/1"
UR_JSON_FORMAT = "ur-joint-targets/1"

RAPID_MAX_LINE = 100      # longest line the RAPID writer emits (characters) ...
RAPID_MAX_STRING = 80     # RAPID string data: at most 80 characters
RAPID_MAX_LINE_ID = 8 + 3 * RAPID_MAX_STRING + 3  # ... except an id line full of \hh escapes (251)
RAPID_MAX_IDENT = 32      # RAPID identifiers: at most 32 characters
RAPID_UNUSED = "9E9"      # value of an unused external axis
JOINT_DECIMALS = 6        # deg
POSITION_DECIMALS = 4     # mm
QUAT_DECIMALS = 9         # quaternion components
RESIDUAL_DECIMALS = 4     # mm
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
    ``predicted_residual_mm``: predicted position error left after correction
    (mm); ``predicted_rot_err_deg``: predicted orientation error (deg), nan when
    not applicable; ``predicted_std_mm``: 3-D predictive standard deviation of the
    residual layer at the corrected joints (GPR), nan when the model has none.
    """

    target_id: str
    q_nominal_deg: tuple[float, ...]
    q_corrected_deg: tuple[float, ...]
    p_command_base_mm: tuple[float, float, float]
    quat_command_wxyz: tuple[float, float, float, float]
    confdata: tuple[int, int, int, int]
    predicted_residual_mm: float
    predicted_rot_err_deg: float = math.nan
    predicted_std_mm: float = math.nan


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


def _as_float(x: Any) -> float | None:
    """``float(x)`` for real numbers (not bool/str), else None."""
    if isinstance(x, (bool, str, bytes)):
        return None
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def _limits(q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Validated joint limits (deg) as float tuples; ValueError when unusable."""
    lo = tuple(_as_float(v) for v in q_min_deg)
    hi = tuple(_as_float(v) for v in q_max_deg)
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
    v = _as_float(value)
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
        f = _as_float(v)
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
    res = _as_float(t.predicted_residual_mm)
    if res is None or not math.isfinite(res) or res < 0:
        out.append(f"predicted_residual_mm must be finite and >= 0, got {t.predicted_residual_mm!r}")
    rot = _as_float(t.predicted_rot_err_deg)
    if rot is None or math.isinf(rot) or rot < 0:
        out.append(f"predicted_rot_err_deg must be nan or finite >= 0, got {t.predicted_rot_err_deg!r}")
    std = _as_float(t.predicted_std_mm)
    if std is None or math.isinf(std) or std < 0:
        out.append(f"predicted_std_mm must be nan or finite >= 0, got {t.predicted_std_mm!r}")
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
    values, when: a field is non-finite or malformed (``predicted_rot_err_deg``
    may be nan); a corrected joint (deg) leaves ``[q_min_deg, q_max_deg]``;
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


def _require_writable(targets: Iterable[CorrectedTarget], q_min_deg: Sequence[float], q_max_deg: Sequence[float],
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


# --------------------------------------------------------------------------
# files


def _fixed(x: float, decimals: int) -> str:
    """``x`` with ``decimals`` decimals, trailing zeros dropped, never ``-0`` (RAPID/URScript literal)."""
    s = f"{float(x):.{decimals}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


# --------------------------------------------------------------------------
# RAPID writer

_RAPID_RESERVED = frozenset("""
ALIAS AND BACKWARD CASE CONNECT CONST DEFAULT DIV DO ELSE ELSEIF ENDFOR ENDFUNC ENDIF ENDMODULE
ENDPROC ENDRECORD ENDTEST ENDTRAP ENDWHILE ERROR EXIT FALSE FOR FROM FUNC GOTO IF INOUT LOCAL MOD
MODULE NOSTEPIN NOT NOVIEW OR PERS PROC RAISE READONLY RECORD RETRY RETURN STEP SYSMODULE TASK TEST
THEN TO TRAP TRUE TRYNEXT UNDO VAR VIEWONLY WHILE WITH XOR""".split())
_RAPID_IDENT_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def _rapid_ident_problem(name: str) -> str | None:
    """Why ``name`` is not a RAPID identifier (None when it is)."""
    if not _RAPID_IDENT_RE.match(name):
        return f"bad identifier '{name}': a letter, then letters, digits or '_'"
    if len(name) > RAPID_MAX_IDENT:
        return f"identifier '{name}' is longer than {RAPID_MAX_IDENT} characters"
    if name.upper() in _RAPID_RESERVED:
        return f"'{name}' is a reserved word"
    return None


def _rapid_string(text: str) -> str:
    """RAPID string literal of ``text`` (ISO 8859-1, at most 80 characters); ValueError otherwise."""
    if len(text) > RAPID_MAX_STRING:
        raise ValueError(f"{text!r}: RAPID strings hold at most {RAPID_MAX_STRING} characters")
    out = []
    for ch in text:
        code = ord(ch)
        if code > 255:
            raise ValueError(f"{text!r}: character {ch!r} is not ISO 8859-1, RAPID cannot hold it")
        if ch == '"':
            out.append('""')
        elif ch == "\\":
            out.append("\\\\")
        elif code < 32 or code >= 127:
            out.append(f"\\{code:02X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _rapid_quat(q: Sequence[float]) -> list[str]:
    """Quaternion (w, x, y, z) renormalised and written with 9 decimals (unit to 1e-8)."""
    v = [float(c) for c in q]
    norm = math.sqrt(sum(c * c for c in v))
    if not math.isfinite(norm) or norm == 0.0:
        raise ValueError(f"quaternion {q!r} cannot be normalised")
    r = [round(c / norm, QUAT_DECIMALS) for c in v]
    # |norm(r) - 1| <= |r - v/|v|| <= 2 * 0.5e-9: always within 1e-8.
    assert abs(math.sqrt(sum(c * c for c in r)) - 1.0) <= 1e-8
    return [_fixed(c, QUAT_DECIMALS) for c in r]


def _rapid_extax(external_axes: Sequence[float] | Mapping[str, Sequence[float]] | None,
                 target_id: str) -> list[str]:
    """The 6 extjoint values (deg or mm) for a target, ``9E9`` for unused axes."""
    if external_axes is None:
        vals: Sequence[float] = ()
    elif isinstance(external_axes, Mapping):
        if target_id not in external_axes:
            raise ValueError(f"external_axes has no values for target {target_id!r}")
        vals = external_axes[target_id]
    else:
        vals = external_axes
    vals = list(vals)
    if len(vals) > 6 or any(_as_float(v) is None or not math.isfinite(_as_float(v)) for v in vals):
        raise ValueError(f"external_axes for {target_id!r}: expected at most 6 finite numbers, got {vals!r}")
    return [_fixed(v, JOINT_DECIMALS) for v in vals] + [RAPID_UNUSED] * (6 - len(vals))


def _agg(parts: Iterable[str]) -> str:
    """RAPID aggregate ``[a,b,...]``."""
    return "[" + ",".join(parts) + "]"


def _split_after_commas(text: str, depth: int | None = None) -> list[str]:
    """Pieces of ``text`` each ending after a comma outside string literals.

    ``depth``: split only at commas nested in exactly that many brackets
    (None: at every comma).
    """
    pieces, start, in_str, level = [], 0, False, 0
    for i, ch in enumerate(text):
        if ch == '"':
            in_str = not in_str
        elif in_str:
            continue
        elif ch == "[":
            level += 1
        elif ch == "]":
            level -= 1
        elif ch == "," and depth in (None, level):
            pieces.append(text[start:i + 1])
            start = i + 1
    pieces.append(text[start:])
    return [p for p in pieces if p]


def _pack(pieces: Sequence[str], first: str, rest: str, width: int) -> list[str]:
    """Greedy fill of ``pieces`` into lines (``first``/``rest`` indents) of at most ``width``."""
    lines, line = [], first
    for piece in pieces:
        if len(line) + len(piece) > width and line.strip():
            lines.append(line)
            line = rest
        line += piece
    lines.append(line)
    return lines


def _wrap(text: str, indent: str, width: int = RAPID_MAX_LINE) -> list[str]:
    """Lines of ``text`` broken after commas so that each fits in ``width`` characters.

    Breaks between the components of an aggregate first, inside them only if
    a component alone is still too long.
    """
    if len(indent) + len(text) <= width:
        return [indent + text]
    cont = indent + "    "
    lines = []
    for k, line in enumerate(_pack(_split_after_commas(text, 1), indent, cont, width)):
        if len(line) <= width:
            lines.append(line)
        else:
            body = line[len(indent if k == 0 else cont):]
            lines += _pack(_split_after_commas(body), indent if k == 0 else cont, cont, width)
    return lines


def _rapid_array(storage: str, type_name: str, name: str, elements: Sequence[str]) -> list[str]:
    """Lines of ``STORAGE type name{N}:=[e1, ..., eN];``, one element per line (wrapped)."""
    lines = [f"    {storage} {type_name} {name}{{{len(elements)}}}:=["]
    for k, element in enumerate(elements):
        lines += _wrap(element + ("," if k < len(elements) - 1 else ""), " " * 8)
    lines.append("    ];")
    return lines


def _rapid_header(module_name: str, n: int, persistent: bool) -> list[str]:
    """The comment block at the top of the module (deterministic: no date)."""
    kind = "PERS" if persistent else "CONST"
    return [
        "    !" + "*" * 70,
        f"    ! {module_name}: {n} corrected target{'' if n == 1 else 's'}.",
        f"    ! Written by {GENERATOR} (format {RAPID_FORMAT}).",
        "    ! Only targets that passed the safety bounds are here; rejected ones are",
        "    ! listed in the rejected-targets CSV.  Index i of every array is one target:",
        "    !   id_cal{i}      source target id",
        "    !   jt_cal{i}      corrected joints (deg), for MoveAbsJ",
        "    !   rt_cal{i}      command pose: position mm, quaternion w,x,y,z, robot base",
        "    !                  frame, confdata cf1,cf4,cf6,cfx, for MoveJ/MoveL",
        "    !   res_cal_mm{i}  predicted residual position error (mm)",
        f"    ! Data are {kind}; unused external axes are 9E9.  Do not edit by hand.",
        "    !" + "*" * 70,
    ]


def render_rapid_module(targets: Iterable[CorrectedTarget], *, module_name: str = "CalTargets",
                        persistent: bool = False, q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                        external_axes: Sequence[float] | Mapping[str, Sequence[float]] | None = None) -> str:
    """Text of the RAPID module for ``targets`` (see :func:`write_rapid_module`)."""
    items = _require_writable(targets, q_min_deg, q_max_deg, n_joints=6, allow_empty=False)
    problem = _rapid_ident_problem(module_name)
    if problem:
        raise ValueError(f"module_name: {problem}")
    storage = "PERS" if persistent else "CONST"
    jt, rt, ids, res = [], [], [], []
    for t in items:
        ext = _agg(_rapid_extax(external_axes, t.target_id))
        joints = _agg(_fixed(q, JOINT_DECIMALS) for q in t.q_corrected_deg)
        jt.append(_agg([joints, ext]))
        pos = _agg(_fixed(p, POSITION_DECIMALS) for p in t.p_command_base_mm)
        conf = _agg(str(int(c)) for c in t.confdata)
        rt.append(_agg([pos, _agg(_rapid_quat(t.quat_command_wxyz)), conf, ext]))
        ids.append(_rapid_string(t.target_id))
        res.append(_fixed(t.predicted_residual_mm, RESIDUAL_DECIMALS))
    lines = [f"MODULE {module_name}", *_rapid_header(module_name, len(items), persistent), "",
             "    ! Number of targets.", f"    CONST num n_cal:={len(items)};",
             "    ! Source target ids.", *_rapid_array(storage, "string", "id_cal", ids),
             "    ! Corrected joints (deg).", *_rapid_array(storage, "jointtarget", "jt_cal", jt),
             "    ! Command poses (mm, quaternion w-first, base frame).",
             *_rapid_array(storage, "robtarget", "rt_cal", rt),
             "    ! Predicted residual position errors (mm).", *_rapid_array(storage, "num", "res_cal_mm", res),
             "ENDMODULE", ""]
    text = "\n".join(lines)
    errors = check_rapid_syntax(text, max_line_len=RAPID_MAX_LINE_ID)
    if errors:  # pragma: no cover - a writer bug; never write an unchecked module
        raise ValueError(f"generated RAPID module is invalid: {errors[0]}")
    return text


def write_rapid_module(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                       module_name: str = "CalTargets", persistent: bool = False,
                       q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                       external_axes: Sequence[float] | Mapping[str, Sequence[float]] | None = None) -> Path:
    """Write an ABB RAPID module of the accepted targets (6 joints) atomically; return the path.

    Arrays ``id_cal{N}`` (string), ``jt_cal{N}`` (jointtarget, deg, 6 decimals),
    ``rt_cal{N}`` (robtarget: mm 4 decimals, quaternion 9 decimals, confdata),
    ``res_cal_mm{N}`` (num, mm) and ``CONST num n_cal``; ``CONST`` data, or
    ``PERS`` when ``persistent``.  ``external_axes``: None (all ``9E9``), up to
    6 values (deg or mm) for every target, or a mapping target id -> values.
    Raises ValueError, writing nothing, for an invalid target or one outside
    ``[q_min_deg, q_max_deg]``, ids over 80 characters or not ISO 8859-1.
    """
    text = render_rapid_module(targets, module_name=module_name, persistent=persistent,
                               q_min_deg=q_min_deg, q_max_deg=q_max_deg, external_axes=external_axes)
    return atomic_write(path, text.encode("ascii"))


# --------------------------------------------------------------------------
# RAPID checker and reader

# Structure of the known data types: an atomic kind ("num", "bool", "string"),
# a tuple of (component, type) pairs, or None (opaque: no initialiser check).
_RAPID_TYPES: dict[str, Any] = {
    "num": "num", "dnum": "num", "byte": "num", "errnum": "num", "intnum": "num",
    "bool": "bool", "string": "string",
    "pos": tuple((c, "num") for c in ("x", "y", "z")),
    "orient": tuple((c, "num") for c in ("q1", "q2", "q3", "q4")),
    "confdata": tuple((c, "num") for c in ("cf1", "cf4", "cf6", "cfx")),
    "extjoint": tuple((f"eax_{c}", "num") for c in "abcdef"),
    "robjoint": tuple((f"rax_{c}", "num") for c in "123456"),
    "pose": (("trans", "pos"), ("rot", "orient")),
    "jointtarget": (("robax", "robjoint"), ("extax", "extjoint")),
    "robtarget": (("trans", "pos"), ("rot", "orient"), ("robconf", "confdata"), ("extax", "extjoint")),
    "loaddata": (("mass", "num"), ("cog", "pos"), ("aom", "orient"), ("ix", "num"), ("iy", "num"),
                 ("iz", "num")),
    "tooldata": (("robhold", "bool"), ("tframe", "pose"), ("tload", "loaddata")),
    "wobjdata": (("robhold", "bool"), ("ufprog", "bool"), ("ufmec", "string"), ("uframe", "pose"),
                 ("oframe", "pose")),
    "speeddata": tuple((c, "num") for c in ("v_tcp", "v_ori", "v_leax", "v_reax")),
    "zonedata": (("finep", "bool"),) + tuple((c, "num") for c in (
        "pzone_tcp", "pzone_ori", "pzone_eax", "zone_ori", "zone_leax", "zone_reax")),
    "clock": None,
}
_MODULE_ATTRS = frozenset({"SYSMODULE", "NOVIEW", "NOSTEPIN", "VIEWONLY", "READONLY"})
_DECL_WORDS = frozenset({"CONST", "PERS", "VAR"})
_ROUTINE_END = {"PROC": "ENDPROC", "FUNC": "ENDFUNC", "TRAP": "ENDTRAP"}
_END_WORDS = frozenset({"ENDIF", "ENDFOR", "ENDWHILE", "ENDTEST", "ENDPROC", "ENDFUNC", "ENDTRAP",
                        "ENDMODULE", "ENDRECORD"})
_MODULE_LEVEL = frozenset({"CONST", "PERS", "VAR", "LOCAL", "TASK", "PROC", "FUNC", "TRAP", "RECORD",
                           "ALIAS", "ENDMODULE", "MODULE"})
_STATEMENT_WORDS = _END_WORDS | {"IF", "ELSEIF", "ELSE", "FOR", "WHILE", "TEST", "CASE", "DEFAULT",
                                 "ERROR", "UNDO", "BACKWARD"} | _MODULE_LEVEL
_CONTINUE_WORDS = frozenset({"AND", "OR", "XOR", "NOT", "DIV", "MOD", "THEN", "DO", "TO", "FROM", "STEP"})
_BINOPS = frozenset({"+", "-", "*", "/", "<", "<=", ">", ">=", "=", "<>", "DIV", "MOD", "AND", "OR", "XOR"})
_OPS = (":=", "<>", "<=", ">=", "+", "-", "*", "/", "<", ">", "=", "(", ")", "[", "]", "{", "}",
        ",", ";", ":", "\\", ".", "%")
_NUM_RE = re.compile(r"0[xX][0-9A-Fa-f]+|0[oO][0-7]+|0[bB][01]+|(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_WORD_RE = re.compile(r"[A-Za-z0-9_]+")
_FLOAT32_MAX = 3.4028234663852886e38


@dataclass(frozen=True)
class RapidExpr:
    """A RAPID initial value that is not a literal (a name or an expression), as source text."""

    text: str


@dataclass(frozen=True)
class _Tok:
    kind: str          # "id", "num", "str", "op", "eof"
    text: str
    line: int
    value: Any = None
    first: bool = False    # first token on its line
    comment: bool = False  # a comment stands between the previous token and this one

    @property
    def up(self) -> str:
        return self.text.upper() if self.kind == "id" else ""


@dataclass
class _Lit:
    value: Any
    kind: str  # "num", "bool", "string"
    line: int
    text: str


@dataclass
class _Agg:
    items: list
    line: int


@dataclass
class _Expr:
    text: str
    line: int


@dataclass
class _Decl:
    storage: str
    type_name: str
    name: str
    dims: tuple
    value: Any
    line: int


class _ParseError(Exception):
    def __init__(self, line: int, message: str) -> None:
        super().__init__(message)
        self.line = line
        self.message = message


def _strip_percent_header(text: str) -> str:
    """Blank an old-style ``%%%`` ... ``%%%`` file header, keeping line numbers."""
    lines = text.split("\n")
    first = next((k for k, s in enumerate(lines) if s.strip()), None)
    if first is None or lines[first].strip() != "%%%":
        return text
    end = next((k for k in range(first + 1, len(lines)) if lines[k].strip() == "%%%"), None)
    if end is None:
        return text
    return "\n".join([""] * (end + 1) + lines[end + 1:])


def _read_string(text: str, i: int, line: int, errors: list[tuple[int, str]]) -> tuple[str, int]:
    """Decode the RAPID string literal starting at ``text[i] == '"'``; return (value, next index)."""
    out, i = [], i + 1
    while True:
        if i >= len(text) or text[i] in "\r\n":
            errors.append((line, "unterminated string literal"))
            return "".join(out), i
        ch = text[i]
        if ch == '"':
            if text.startswith('""', i):
                out.append('"')
                i += 2
                continue
            value = "".join(out)
            if len(value) > RAPID_MAX_STRING:
                errors.append((line, f"string literal longer than {RAPID_MAX_STRING} characters"))
            return value, i + 1
        if ch == "\\":
            hexa = text[i + 1:i + 3]
            if hexa.startswith("\\"):
                out.append("\\")
                i += 2
            elif len(hexa) == 2 and all(c in "0123456789abcdefABCDEF" for c in hexa):
                out.append(chr(int(hexa, 16)))
                i += 3
            else:
                errors.append((line, f"bad escape '\\{text[i + 1:i + 2]}' in string (use \\\\ or \\hh)"))
                i += 1
            continue
        out.append(ch)
        i += 1


def _num_value(text: str) -> float | int:
    """Value of a RAPID numeric literal."""
    low = text.lower()
    for prefix, base in (("0x", 16), ("0o", 8), ("0b", 2)):
        if low.startswith(prefix):
            return int(text[2:], base)
    if re.fullmatch(r"[0-9]+", text):
        return int(text)
    return float(text)


def _tokenize(text: str, errors: list[tuple[int, str]]) -> list[_Tok]:
    """RAPID tokens of ``text``; lexical errors go to ``errors`` as (line, message)."""
    toks: list[_Tok] = []
    i, line, first, comment = 0, 1, True, False

    def add(kind: str, s: str, value: Any = None) -> None:
        nonlocal first, comment
        toks.append(_Tok(kind, s, line, value, first, comment))
        first = comment = False

    while i < len(text):
        ch = text[i]
        if ch == "\n":
            line, first, i = line + 1, True, i + 1
        elif ch in " \t\r\f":
            i += 1
        elif ch == "!":
            end = text.find("\n", i)
            i, comment = (len(text) if end < 0 else end), True
        elif ch == '"':
            value, i = _read_string(text, i, line, errors)
            add("str", value, value)
        elif ch.isdigit() or (ch == "." and text[i + 1:i + 2].isdigit()):
            m = _NUM_RE.match(text, i)
            tail = _WORD_RE.match(text, m.end())
            if tail:
                bad = text[i:tail.end()]
                errors.append((line, f"bad identifier or number '{bad}'"))
                i = tail.end()
                add("id", bad)
                continue
            value = _num_value(m.group())
            if abs(value) > _FLOAT32_MAX:
                errors.append((line, f"number {m.group()} out of range"))
            add("num", m.group(), value)
            i = m.end()
        elif ch.isascii() and (ch.isalpha() or ch == "_"):
            m = _WORD_RE.match(text, i)
            word = m.group()
            problem = None if ch != "_" else f"bad identifier '{word}': must start with a letter"
            if problem is None and len(word) > RAPID_MAX_IDENT:
                problem = f"identifier '{word}' is longer than {RAPID_MAX_IDENT} characters"
            if problem:
                errors.append((line, problem))
            add("id", word)
            i = m.end()
        else:
            op = next((o for o in _OPS if text.startswith(o, i)), None)
            if op is None:
                errors.append((line, f"unexpected character {ch!r}"))
                i += 1
                continue
            add("op", op)
            i += len(op)
    toks.append(_Tok("eof", "end of file", line, None, True, comment))
    return toks


class _RapidParser:
    """Recursive-descent checker of a RAPID module; collects errors and module-level declarations."""

    def __init__(self, text: str, extra_types: Iterable[str] = ()) -> None:
        self.lex_errors: list[tuple[int, str]] = []
        self.errors: list[tuple[int, str]] = []
        self.toks = _tokenize(_strip_percent_header(text), self.lex_errors)
        self.i = 0
        self.in_stmt = False
        self.types = dict(_RAPID_TYPES)
        self.types.update({t.lower(): None for t in extra_types})
        self.decls: dict[str, _Decl] = {}

    # -- token access
    def peek(self) -> _Tok:
        return self.toks[self.i]

    def next(self) -> _Tok:
        tok = self.toks[self.i]
        if self.in_stmt and tok.comment and tok.kind != "eof":
            self.err(tok.line, "comment inside a statement (a RAPID comment must stand on its own)")
        if tok.kind != "eof":
            self.i += 1
        return tok

    def err(self, line: int, message: str) -> None:
        self.errors.append((line, message))

    def is_op(self, text: str) -> bool:
        return self.peek().kind == "op" and self.peek().text == text

    def expect_op(self, text: str, what: str) -> _Tok:
        tok = self.peek()
        if tok.kind != "op" or tok.text != text:
            raise _ParseError(tok.line, f"expected '{text}' {what}, got '{tok.text}'")
        return self.next()

    def name(self, what: str) -> _Tok:
        """An identifier token that may name a declared thing."""
        tok = self.peek()
        if tok.kind != "id":
            raise _ParseError(tok.line, f"expected {what}, got '{tok.text}'")
        if tok.up in _RAPID_RESERVED:  # form and length are reported by the tokenizer
            raise _ParseError(tok.line, f"{what}: '{tok.text}' is a reserved word")
        return self.next()

    def sync(self, module_level: bool) -> None:
        """Skip to after the next ';', or to the next line that starts a module item (or any line)."""
        self.in_stmt = False
        while self.peek().kind != "eof":
            tok = self.peek()
            if tok.kind == "op" and tok.text == ";":
                self.next()
                return
            if tok.first and (tok.up in _MODULE_LEVEL or not module_level):
                return
            self.next()

    # -- module
    def parse_module(self) -> None:
        tok = self.next()
        if tok.up != "MODULE":
            self.err(tok.line, f"expected 'MODULE name' at the start, got '{tok.text}'")
            return
        try:
            name = self.name("module name")
            if self.is_op("("):
                self.module_attributes()
        except _ParseError as e:
            self.err(e.line, e.message)
            return
        self.module_items(name)
        if self.peek().kind != "eof":
            self.err(self.peek().line, f"text after ENDMODULE: '{self.peek().text}'")

    def module_attributes(self) -> None:
        self.next()
        while True:
            tok = self.next()
            if tok.up not in _MODULE_ATTRS:
                raise _ParseError(tok.line, f"unknown module attribute '{tok.text}'")
            if self.is_op(")"):
                self.next()
                return
            self.expect_op(",", "between module attributes")

    def module_items(self, module: _Tok) -> None:
        while True:
            tok, before = self.peek(), self.i
            up = tok.up
            try:
                if tok.kind == "eof":
                    self.err(tok.line, f"missing ENDMODULE for MODULE {module.text} (line {module.line})")
                    return
                if up == "ENDMODULE":
                    self.next()
                    return
                if up in ("LOCAL", "TASK"):
                    after = self.toks[self.i + 1].up
                    if after in _ROUTINE_END and up == "LOCAL":
                        self.routine()
                    else:
                        self.declaration(module_level=True)
                elif up in _DECL_WORDS:
                    self.declaration(module_level=True)
                elif up in _ROUTINE_END:
                    self.routine()
                elif up == "RECORD":
                    self.record()
                elif up == "ALIAS":
                    self.next()
                    base, alias = self.name("data type"), self.name("alias name")
                    self.types[alias.text.lower()] = self.types.get(base.text.lower())
                    self.expect_op(";", "after ALIAS")
                elif up == "MODULE":
                    self.err(tok.line, f"MODULE inside MODULE {module.text}: missing ENDMODULE?")
                    return
                else:
                    raise _ParseError(tok.line, f"unexpected '{tok.text}' at module level")
            except _ParseError as e:
                self.err(e.line, e.message)
                self.sync(module_level=True)
                if self.i == before:
                    self.next()

    def record(self) -> None:
        start = self.next()
        name = self.name("record name")
        self.types[name.text.lower()] = None
        while self.peek().up != "ENDRECORD":
            if self.peek().kind == "eof" or self.peek().up in _MODULE_LEVEL:
                raise _ParseError(start.line, f"RECORD {name.text} without ENDRECORD")
            self.type_name()
            self.name("record component")
            self.expect_op(";", "after record component")
        self.next()

    def type_name(self) -> str:
        tok = self.name("data type")
        if tok.text.lower() not in self.types:
            raise _ParseError(tok.line, f"unknown data type '{tok.text}'")
        return tok.text.lower()

    # -- declarations
    def declaration(self, module_level: bool) -> None:
        start = self.next()
        try:
            self.in_stmt = True
            storage = self.next().up if start.up in ("LOCAL", "TASK") else start.up
            if storage == "PERS" and not module_level:
                raise _ParseError(start.line, "PERS data must be declared at module level")
            type_name = self.type_name()
            name = self.name("data name")
            dims = self.dimensions() if self.is_op("{") else ()
            value = None
            if self.is_op(":="):
                self.next()
                value = self.expression()
            elif storage == "CONST":
                raise _ParseError(name.line, f"CONST {name.text} needs an initial value ':='")
            tok = self.peek()
            if not (tok.kind == "op" and tok.text == ";"):
                raise _ParseError(self.toks[self.i - 1].line, f"missing ';' after the declaration of "
                                                              f"'{name.text}' (got '{tok.text}')")
            self.next()
            self.in_stmt = False
        except _ParseError as e:
            self.err(e.line, e.message)
            self.sync(module_level)
            return
        decl = _Decl(storage, type_name, name.text, dims, value, start.line)
        self.check_value(decl)
        if module_level:
            key = name.text.lower()
            if key in self.decls:
                self.err(name.line, f"'{name.text}' already declared at line {self.decls[key].line}")
            else:
                self.decls[key] = decl

    def dimensions(self) -> tuple:
        self.next()
        dims: list[Any] = []
        while True:
            tok = self.next()
            if tok.kind == "num" and isinstance(tok.value, int) and tok.value > 0:
                dims.append(tok.value)
            elif tok.kind == "id" and not _rapid_ident_problem(tok.text):
                dims.append(tok.text)  # a named constant: not checked
            else:
                raise _ParseError(tok.line, f"array dimension must be an integer > 0, got '{tok.text}'")
            if self.is_op("}"):
                self.next()
                break
            self.expect_op(",", "between array dimensions")
        if len(dims) > 3:
            raise _ParseError(tok.line, "arrays have at most 3 dimensions")
        return tuple(dims)

    # -- values
    def expression(self) -> Any:
        """expr := term {binop term}; a lone literal or aggregate stays structured."""
        start = self.i
        node = self.term()
        while self.peek().text.upper() in _BINOPS and self.peek().kind in ("op", "id"):
            self.next()
            self.term()
            node = None
        if node is None:
            return _Expr(" ".join(t.text for t in self.toks[start:self.i]), self.toks[start].line)
        return node

    def term(self) -> Any:
        tok = self.peek()
        if tok.kind == "op" and tok.text in "+-" or tok.up == "NOT":
            self.next()
            inner = self.term()
            if isinstance(inner, _Lit) and inner.kind == "num" and tok.text in "+-":
                value = -inner.value if tok.text == "-" else inner.value
                return _Lit(value, "num", tok.line, tok.text + inner.text)
            return _Expr(tok.text + " " + getattr(inner, "text", "..."), tok.line)
        return self.primary()

    def primary(self) -> Any:
        tok = self.next()
        if tok.kind == "num":
            return _Lit(tok.value, "num", tok.line, tok.text)
        if tok.kind == "str":
            return _Lit(tok.value, "string", tok.line, '"' + tok.text + '"')
        if tok.up in ("TRUE", "FALSE"):
            return _Lit(tok.up == "TRUE", "bool", tok.line, tok.up)
        if tok.kind == "op" and tok.text == "[":
            return self.aggregate(tok)
        if tok.kind == "op" and tok.text == "(":
            inner = self.expression()
            self.expect_op(")", f"to close '(' of line {tok.line}")
            return _Expr(f"({getattr(inner, 'text', '...')})", tok.line)
        if tok.kind == "id" and tok.up not in _RAPID_RESERVED:
            return self.reference(tok)
        raise _ParseError(tok.line, f"expected a value, got '{tok.text}'")

    def reference(self, tok: _Tok) -> _Expr:
        """A name with optional {index}, (arguments) and .component parts."""
        start = self.i - 1
        while True:
            if self.is_op("{") or self.is_op("("):
                self.skip_group(self.next())
            elif self.is_op("."):
                self.next()
                self.name("record component")
            else:
                break
        return _Expr("".join(t.text for t in self.toks[start:self.i]), tok.line)

    def skip_group(self, open_tok: _Tok) -> None:
        """Skip to the bracket closing ``open_tok`` (brackets must nest)."""
        pairs = {"(": ")", "[": "]", "{": "}"}
        stack = [open_tok]
        while stack:
            tok = self.next()
            if tok.kind == "eof" or (tok.kind == "op" and tok.text == ";"):
                o = stack[-1]
                raise _ParseError(tok.line, f"unbalanced brackets: '{o.text}' of line {o.line} is not closed")
            if tok.kind == "op" and tok.text in pairs:
                stack.append(tok)
            elif tok.kind == "op" and tok.text in ")]}":
                if pairs[stack[-1].text] != tok.text:
                    raise _ParseError(tok.line, f"unbalanced brackets: '{tok.text}' closes "
                                                f"'{stack[-1].text}' of line {stack[-1].line}")
                stack.pop()

    def aggregate(self, open_tok: _Tok) -> _Agg:
        items = []
        if self.is_op("]"):
            raise _ParseError(open_tok.line, "empty aggregate '[]'")
        while True:
            items.append(self.expression())
            tok = self.peek()
            if tok.kind == "op" and tok.text == ",":
                self.next()
            elif tok.kind == "op" and tok.text == "]":
                self.next()
                return _Agg(items, open_tok.line)
            else:
                raise _ParseError(tok.line, f"unbalanced brackets: expected ',' or ']' in the aggregate "
                                            f"opened at line {open_tok.line}, got '{tok.text}'")

    # -- structure of initial values
    def check_value(self, decl: _Decl) -> None:
        if decl.value is None:
            return
        if decl.dims:
            self.check_array(decl.value, decl.dims, decl.type_name, decl.name)
        else:
            self.check_type(decl.value, decl.type_name, decl.name)

    def check_array(self, node: Any, dims: tuple, type_name: str, where: str) -> None:
        if isinstance(node, _Expr):
            return
        if not isinstance(node, _Agg):
            self.err(node.line, f"{where}: an array needs an aggregate [...] initial value")
            return
        if isinstance(dims[0], int) and len(node.items) != dims[0]:
            self.err(node.line, f"dimension mismatch: {where} is declared with {dims[0]} elements, "
                                f"initialised with {len(node.items)}")
            return
        for k, item in enumerate(node.items, 1):
            if len(dims) > 1:
                self.check_array(item, dims[1:], type_name, f"{where}{{{k}}}")
            else:
                self.check_type(item, type_name, f"{where}{{{k}}}")

    def check_type(self, node: Any, type_name: str, where: str) -> None:
        spec = self.types.get(type_name)
        if spec is None or isinstance(node, _Expr):
            return
        if isinstance(spec, str):
            if isinstance(node, _Agg):
                self.err(node.line, f"{where}: {type_name} takes one value, got an aggregate of "
                                    f"{len(node.items)} elements")
            elif node.kind != spec:
                self.err(node.line, f"{where}: expected a {spec} value, got {node.text}")
            return
        if not isinstance(node, _Agg):
            self.err(node.line, f"{where}: {type_name} needs an aggregate of {len(spec)} components, "
                                f"got {node.text}")
            return
        if len(node.items) != len(spec):
            self.err(node.line, f"{where}: {type_name} needs {len(spec)} components, got {len(node.items)}")
            return
        for (component, sub), item in zip(spec, node.items):
            self.check_type(item, sub, f"{where}.{component}")

    # -- routines
    def routine(self) -> None:
        if self.peek().up == "LOCAL":
            self.next()
        kw = self.next()
        if kw.up == "FUNC":
            self.type_name()
        name = self.name(f"{kw.up} name")
        if kw.up != "TRAP":
            self.skip_group(self.expect_op("(", f"after {kw.up} {name.text}"))
        self.body(kw.up, name)

    def body(self, kind: str, name: _Tok) -> None:
        """Statements up to the routine's END word, checking nested blocks and ';'."""
        stack = [(_ROUTINE_END[kind], f"{kind} {name.text}", name.line)]
        while stack:
            tok, before = self.peek(), self.i
            try:
                if tok.kind == "eof" or tok.up in _MODULE_LEVEL - _DECL_WORDS - {"LOCAL"}:
                    for end, opener, line in reversed(stack):
                        self.err(line, f"missing {end} for {opener} (line {line})")
                    return
                if tok.up in _DECL_WORDS or tok.up == "LOCAL":
                    self.declaration(module_level=False)
                elif tok.up in _END_WORDS:
                    self.close_block(stack)
                else:
                    self.statement(stack)
            except _ParseError as e:
                self.err(e.line, e.message)
                self.sync(module_level=False)
                if self.i == before:
                    self.next()

    def close_block(self, stack: list) -> None:
        tok = self.next()
        ends = [end for end, _, _ in stack]
        if tok.up == ends[-1]:
            stack.pop()
            return
        end, opener, line = stack[-1]
        if tok.up in ends:  # close the inner blocks that were left open
            while stack[-1][0] != tok.up:
                end, opener, line = stack.pop()
                self.err(line, f"missing {end} for {opener} (line {line}) before {tok.up}")
            stack.pop()
        else:
            self.err(tok.line, f"{tok.up} does not close {opener} (line {line}); expected {end}")

    def statement(self, stack: list) -> None:
        tok = self.next()
        up, top = tok.up, stack[-1][0]
        if up == "IF":
            if self.scan({"THEN", ";"}, tok) == "THEN":
                stack.append(("ENDIF", "IF", tok.line))
        elif up in ("ELSEIF", "ELSE"):
            if top != "ENDIF":
                raise _ParseError(tok.line, f"{up} outside IF ... ENDIF")
            if up == "ELSEIF":
                self.scan({"THEN"}, tok)
        elif up in ("FOR", "WHILE"):
            self.scan({"DO"}, tok)
            stack.append((f"END{up}", up, tok.line))
        elif up == "TEST":
            self.scan({"CASE", "DEFAULT", "ENDTEST"}, tok, consume=False)
            stack.append(("ENDTEST", "TEST", tok.line))
        elif up in ("CASE", "DEFAULT"):
            if top != "ENDTEST":
                raise _ParseError(tok.line, f"{up} outside TEST ... ENDTEST")
            self.scan({":"}, tok)
        elif up in ("ERROR", "UNDO", "BACKWARD"):
            if len(stack) != 1:
                raise _ParseError(tok.line, f"{up} handler inside a block: missing {top}?")
            if up == "ERROR" and self.is_op("(") and not self.peek().first:
                self.skip_group(self.next())
        elif tok.kind == "op" and tok.text == ";":
            raise _ParseError(tok.line, "empty statement ';'")
        elif tok.kind == "id" and self.is_op(":") and tok.up not in _RAPID_RESERVED:
            self.next()  # a label
        else:
            self.scan({";"}, tok, first=tok)

    def scan(self, terminators: set[str], start: _Tok, consume: bool = True, first: _Tok | None = None) -> str:
        """Consume a statement up to one of ``terminators`` at bracket depth 0; return it.

        ``first``: the statement's first token when already consumed.
        """
        pairs = {"(": ")", "[": "]", "{": "}"}
        stack: list[_Tok] = [first] if first is not None and first.kind == "op" and first.text in pairs else []
        prev: _Tok | None = first
        self.in_stmt = True
        try:
            while True:
                tok = self.peek()
                word = tok.up or (tok.text if tok.kind == "op" else "")
                if tok.kind == "eof":
                    raise _ParseError(start.line, f"statement of line {start.line} is not terminated")
                if not stack:
                    if word in terminators:
                        if consume:
                            self.next()
                        return word
                    if prev is not None and tok.first and self._line_break_ends(prev, tok):
                        want = " or ".join(sorted(f"'{t}'" for t in terminators))
                        raise _ParseError(prev.line, f"missing {want} at the end of the line")
                elif tok.kind == "op" and tok.text == ";":
                    raise _ParseError(tok.line, f"unbalanced brackets: '{stack[-1].text}' of line "
                                                f"{stack[-1].line} is not closed")
                if tok.kind == "op" and tok.text in pairs:
                    stack.append(tok)
                elif tok.kind == "op" and tok.text in ")]}":
                    if not stack or pairs[stack[-1].text] != tok.text:
                        raise _ParseError(tok.line, f"unbalanced brackets: unexpected '{tok.text}'")
                    stack.pop()
                prev = self.next()
        finally:
            self.in_stmt = False

    @staticmethod
    def _line_break_ends(prev: _Tok, tok: _Tok) -> bool:
        """True when ``tok`` (first on its line) cannot continue the statement ending with ``prev``."""
        if tok.up in _STATEMENT_WORDS:
            return True
        ends_value = prev.kind in ("num", "str") or (prev.kind == "id" and prev.up not in _CONTINUE_WORDS) \
            or (prev.kind == "op" and prev.text in ")]}")
        return ends_value and tok.kind == "id" and tok.up not in _CONTINUE_WORDS


def _run_rapid_parser(text: str, max_line_len: int | None, extra_types: Iterable[str]) -> _RapidParser:
    parser = _RapidParser(text, extra_types)
    parser.parse_module()
    if max_line_len is not None:
        for k, line in enumerate(text.split("\n"), 1):
            if len(line.rstrip("\r")) > max_line_len:
                parser.err(k, f"line longer than {max_line_len} characters ({len(line)})")
    return parser


def _messages(parser: _RapidParser) -> list[str]:
    found = sorted(set(parser.lex_errors) | set(parser.errors), key=lambda e: e[0])
    return [f"line {line}: {message}" for line, message in found]


def check_rapid_syntax(text: str, *, max_line_len: int | None = None,
                       extra_types: Iterable[str] = ()) -> list[str]:
    """One-line errors ``"line N: ..."`` of a RAPID module text (empty list: OK).

    Checks: ``MODULE name`` ... ``ENDMODULE`` and balanced PROC/FUNC/TRAP,
    IF/FOR/WHILE/TEST blocks; declarations ``[LOCAL|TASK] CONST|PERS|VAR type
    name[{d1[,d2[,d3]]}] [:= value];`` with known data types (plus RECORDs of
    the module and ``extra_types``); identifiers (letter first, <= 32
    characters, not reserved); literals (numbers, strings with ``""``, ``\\\\``
    and ``\\hh``, at most 80 characters, TRUE/FALSE); balanced aggregates;
    element counts against array dimensions and the structure of pos, orient,
    confdata, jointtarget, robtarget, tooldata, wobjdata, ...; ``;`` after
    statements; comments ``!`` standing alone; optionally line lengths.
    """
    return _messages(_run_rapid_parser(text, max_line_len, extra_types))


def _to_python(node: Any) -> Any:
    if node is None:
        return None
    if isinstance(node, _Agg):
        return [_to_python(item) for item in node.items]
    if isinstance(node, _Lit):
        return node.value
    return RapidExpr(node.text)


def parse_rapid_module(text: str, *, extra_types: Iterable[str] = ()) -> dict[str, Any]:
    """Module-level data of a RAPID module: name -> value, in declaration order.

    Values are nested lists of int (integer literals), float, str (decoded
    strings) and bool; a non-literal value is a :class:`RapidExpr`; a
    declaration without initial value maps to None.  Raises ValueError listing
    the syntax errors when :func:`check_rapid_syntax` finds any.
    """
    parser = _run_rapid_parser(text, None, extra_types)
    errors = _messages(parser)
    if errors:
        raise ValueError(f"RAPID syntax errors: {'; '.join(errors)}")
    return {decl.name: _to_python(decl.value) for decl in parser.decls.values()}


# --------------------------------------------------------------------------
# Universal Robots


def render_ur_json(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                   q_max_deg: Sequence[float]) -> str:
    """Text of the UR joint-targets JSON (see :func:`write_ur_json`)."""
    items = _require_writable(targets, q_min_deg, q_max_deg, n_joints=6)
    doc = {
        "format": UR_JSON_FORMAT,
        "units": {"q": "rad", "predicted_residual": "mm"},
        "targets": [{
            "id": t.target_id,
            "q_rad": [math.radians(float(q)) for q in t.q_corrected_deg],
            "q_deg": [float(q) for q in t.q_corrected_deg],
            "q_nominal_rad": [math.radians(float(q)) for q in t.q_nominal_deg],
            "predicted_residual_mm": float(t.predicted_residual_mm),
            "predicted_std_mm": None if math.isnan(float(t.predicted_std_mm)) else float(t.predicted_std_mm),
        } for t in items],
    }
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def write_ur_json(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                  q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> Path:
    """Write the accepted targets (6 joints) as UR JSON atomically; return the path.

    ``{"format": "ur-joint-targets/1", "units": {...}, "targets": [{"id",
    "q_rad", "q_deg", "q_nominal_rad", "predicted_residual_mm"}]}``; angles in
    rad (``q_deg`` in deg), full float precision.  ValueError, writing
    nothing, for an invalid target or one outside ``[q_min_deg, q_max_deg]``.
    """
    return atomic_write(path, render_ur_json(targets, q_min_deg=q_min_deg, q_max_deg=q_max_deg).encode("ascii"))


_UR_KEYWORDS = frozenset({"def", "end", "if", "elif", "else", "while", "for", "thread", "return", "break",
                          "continue", "global", "local", "True", "False", "not", "and", "or", "xor", "run",
                          "kill", "join", "halt", "sec", "enter_critical", "exit_critical"})
_UR_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _ur_motion_bound(value: float, name: str, upper: float) -> float:
    """A URScript speed/acceleration in (0, upper]; ValueError otherwise."""
    v = _as_float(value)
    if v is None or not math.isfinite(v) or not 0 < v <= upper:
        raise ValueError(f"{name}: expected a number in (0, {upper:g}], got {value!r}")
    return v


def render_urscript(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                    q_max_deg: Sequence[float], a_rad_s2: float = 0.5, v_rad_s: float = 0.3,
                    name: str = "cal_targets") -> str:
    """Text of the URScript program (see :func:`write_urscript`)."""
    items = _require_writable(targets, q_min_deg, q_max_deg, n_joints=6, allow_empty=False)
    a = _ur_motion_bound(a_rad_s2, "a_rad_s2", UR_MAX_A_RAD_S2)
    v = _ur_motion_bound(v_rad_s, "v_rad_s", UR_MAX_V_RAD_S)
    if not _UR_NAME_RE.match(name) or name in _UR_KEYWORDS:
        raise ValueError(f"name: {name!r} is not a URScript function name")
    lines = [f"# {name}: {len(items)} corrected targets, written by {GENERATOR} ({URSCRIPT_FORMAT}).",
             "# Joints in rad; each target: '# <target id> predicted_residual_mm=<mm>' then movej.",
             "# Only targets that passed the safety bounds are here.",
             f"def {name}():"]
    for t in items:
        q = ",".join(_fixed(math.radians(float(x)), UR_RAD_DECIMALS) for x in t.q_corrected_deg)
        lines.append(f"  # {t.target_id} predicted_residual_mm={_fixed(t.predicted_residual_mm, RESIDUAL_DECIMALS)}")
        lines.append(f"  movej([{q}], a={_fixed(a, 6)}, v={_fixed(v, 6)})")
    lines += ["end", ""]
    text = "\n".join(lines)
    errors = check_urscript_syntax(text)
    if errors:  # pragma: no cover - a writer bug
        raise ValueError(f"generated URScript is invalid: {errors[0]}")
    return text


def write_urscript(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                   q_min_deg: Sequence[float], q_max_deg: Sequence[float], a_rad_s2: float = 0.5,
                   v_rad_s: float = 0.3, name: str = "cal_targets") -> Path:
    """Write a URScript program ``def name(): movej(...) ... end`` atomically; return the path.

    One ``movej([q1..q6] rad, a=a_rad_s2 rad/s^2, v=v_rad_s rad/s)`` per
    target, preceded by ``# <id> predicted_residual_mm=<mm>``.  ValueError,
    writing nothing, for an invalid target, one outside the joint limits
    (deg), or a/v outside (0, 40] rad/s^2 / (0, pi] rad/s.
    """
    text = render_urscript(targets, q_min_deg=q_min_deg, q_max_deg=q_max_deg, a_rad_s2=a_rad_s2,
                           v_rad_s=v_rad_s, name=name)
    return atomic_write(path, text.encode("utf-8"))


def _strip_ur_comment(line: str) -> str:
    """``line`` without its ``#`` comment (``#`` inside string literals kept)."""
    quote = None
    for k, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:k]
    return line


def _ur_bracket_problem(code: str) -> str | None:
    """Unbalanced (), [] or {} on one line of URScript (None when balanced)."""
    pairs, stack = {")": "(", "]": "[", "}": "{"}, []
    for ch in re.sub(r"\"[^\"]*\"|'[^']*'", "", code):
        if ch in "([{":
            stack.append(ch)
        elif ch in pairs:
            if not stack or stack.pop() != pairs[ch]:
                return f"unbalanced '{ch}'"
    return f"unclosed '{stack[-1]}'" if stack else None


def _ur_block(code: str, stack: list[tuple[str, int]], lineno: int) -> str | None:
    """Track def/thread/if/while/for ... end blocks; return an error or None."""
    word = re.match(r"[A-Za-z_]\w*", code)
    word = word.group() if word else ""
    if word in ("def", "thread"):
        if not re.fullmatch(rf"{word}\s+[A-Za-z_]\w*\s*\(.*\)\s*:", code):
            return f"malformed '{word}' line"
        stack.append((word, lineno))
    elif word in ("if", "while", "for"):
        if not code.endswith(":"):
            return f"'{word}' line must end with ':'"
        stack.append((word, lineno))
    elif word in ("elif", "else"):
        if not stack or stack[-1][0] != "if" or not code.endswith(":"):
            return f"'{word}' outside an if block"
    elif word == "end" and code == "end":
        if not stack:
            return "'end' without an open block"
        stack.pop()
    return None


def check_urscript_syntax(text: str) -> list[str]:
    """One-line errors ``"line N: ..."`` of a URScript program (empty list: OK).

    A sanity check, not a full parser: def/thread/if/while/for blocks closed
    by ``end``, ``elif``/``else`` inside ``if``, brackets balanced on each
    line, every number finite and no ``nan``/``inf`` names.
    """
    errors: list[str] = []
    stack: list[tuple[str, int]] = []
    for lineno, raw in enumerate(text.split("\n"), 1):
        code = _strip_ur_comment(raw).strip()
        if not code:
            continue
        problems = [_ur_bracket_problem(code), _ur_block(code, stack, lineno)]
        bare = re.sub(r"\"[^\"]*\"|'[^']*'", "", code)
        for word in re.findall(r"[A-Za-z_]\w*", bare):
            if word.lower() in ("nan", "inf", "infinity"):
                problems.append(f"non-finite value '{word}'")
        for number in re.findall(r"(?<![\w.])\d+\.?\d*(?:[eE][+-]?\d+)?", bare):
            if not math.isfinite(float(number)):
                problems.append(f"non-finite number '{number}'")
        errors += [f"line {lineno}: {p}" for p in problems if p]
    errors += [f"line {line}: '{word}' block is not closed by 'end'" for word, line in stack]
    return errors


# --------------------------------------------------------------------------
# CSV


def _csv_float(x: float) -> str:
    """Shortest exact text of a float ('nan' for nan)."""
    return repr(float(x))


def _csv_header(n: int, with_std: bool = True) -> list[str]:
    return (["target_id"] + [f"q{j}" for j in range(1, n + 1)] + [f"q{j}_nominal" for j in range(1, n + 1)]
            + ["x_cmd", "y_cmd", "z_cmd", "qw", "qx", "qy", "qz", "cf1", "cf4", "cf6", "cfx",
               "predicted_residual_mm", "predicted_rot_err_deg"] + (["predicted_std_mm"] if with_std else []))


def render_targets_csv(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                       q_max_deg: Sequence[float]) -> str:
    """Text of the targets CSV (see :func:`write_targets_csv`)."""
    items = _require_writable(targets, q_min_deg, q_max_deg)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    with_std = any(not math.isnan(float(t.predicted_std_mm)) for t in items)   # no all-nan column
    writer.writerow(_csv_header(len(q_min_deg), with_std))
    for t in items:
        writer.writerow([t.target_id, *map(_csv_float, t.q_corrected_deg), *map(_csv_float, t.q_nominal_deg),
                         *map(_csv_float, t.p_command_base_mm), *map(_csv_float, t.quat_command_wxyz),
                         *(str(int(c)) for c in t.confdata), _csv_float(t.predicted_residual_mm),
                         _csv_float(t.predicted_rot_err_deg)]
                        + ([_csv_float(t.predicted_std_mm)] if with_std else []))
    return buf.getvalue()


def write_targets_csv(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                      q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> Path:
    """Write the accepted targets as CSV atomically; return the path.

    Columns ``target_id, q1..qn`` (corrected, deg), ``q1_nominal..qn_nominal``
    (deg), ``x_cmd, y_cmd, z_cmd`` (mm, base), ``qw, qx, qy, qz``, ``cf1, cf4,
    cf6, cfx``, ``predicted_residual_mm``, ``predicted_rot_err_deg``,
    ``predicted_std_mm`` (only when some target has one: GPR layer).  Floats are written exactly (``repr``), so
    :func:`read_targets_csv` gives back identical values.  ValueError, writing
    nothing, for an invalid target or one outside ``[q_min_deg, q_max_deg]``.
    """
    text = render_targets_csv(targets, q_min_deg=q_min_deg, q_max_deg=q_max_deg)
    return atomic_write(path, text.encode("utf-8"))


def read_targets_csv(path: str | os.PathLike) -> list[CorrectedTarget]:
    """Targets from a CSV written by :func:`write_targets_csv`; ValueError on a malformed file."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{path}: empty file")
    header = rows[0]
    n = sum(1 for h in header if re.fullmatch(r"q[0-9]+", h))
    with_std = header[-1:] == ["predicted_std_mm"]
    if n == 0 or header != _csv_header(n, with_std):
        raise ValueError(f"{path}: not a targets CSV header: {','.join(header)}")
    out = []
    for k, row in enumerate(rows[1:], 2):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {k}: {len(row)} fields, expected {len(header)}")
        try:
            nums = [float(v) for v in row[1:2 * n + 8]]
            conf = tuple(int(v) for v in row[2 * n + 8:2 * n + 12])
            res, rot = float(row[2 * n + 12]), float(row[2 * n + 13])
            std = float(row[2 * n + 14]) if with_std else math.nan
        except ValueError as e:
            raise ValueError(f"{path}: line {k}: {e}") from None
        out.append(CorrectedTarget(row[0], tuple(nums[n:2 * n]), tuple(nums[:n]), tuple(nums[2 * n:2 * n + 3]),
                                   tuple(nums[2 * n + 3:2 * n + 7]), conf, res, rot, std))
    return out


def write_rejected_csv(path: str | os.PathLike, rejected: Iterable[Rejected]) -> Path:
    """Write ``target_id,reason`` rows of the rejected targets atomically; return the path."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["target_id", "reason"])
    for r in rejected:
        writer.writerow([r.target_id, " ".join(str(r.reason).split())])
    return atomic_write(path, buf.getvalue().encode("utf-8"))
