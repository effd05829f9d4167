"""ABB RAPID module of corrected targets (:func:`render_rapid_module`, :func:`write_rapid_module`)."""

from __future__ import annotations

import math
import os
import textwrap
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from drivers.abb_axes import AbbAxes, axes_layout
from drivers.rapid import check_rapid_syntax
from drivers.rapid.literals import (RAPID_MAX_LINE_ID, RAPID_UNUSED, rapid_aggregate, fixed_literal, rapid_array_lines,
                                    rapid_ident_problem, rapid_string)

from campaign.io.durable import atomic_write
from .accuracy import PREDICTED_ERROR_METHOD
from .bounds import (GENERATOR, JOINT_DECIMALS, POSITION_DECIMALS, QUAT_DECIMALS, RAPID_FORMAT, ERROR_DECIMALS,
                     CorrectedTarget, as_float, require_writable)

def _rapid_quat(q: Sequence[float]) -> list[str]:
    """Quaternion (w, x, y, z) renormalised and written with 9 decimals (unit to 1e-8)."""
    v = [float(c) for c in q]
    norm = math.sqrt(sum(c * c for c in v))
    if not math.isfinite(norm) or norm == 0.0:
        raise ValueError(f"quaternion {q!r} cannot be normalised")
    r = [round(c / norm, QUAT_DECIMALS) for c in v]
    # |norm(r) - 1| <= |r - v/|v|| <= 2 * 0.5e-9: always within 1e-8.
    assert abs(math.sqrt(sum(c * c for c in r)) - 1.0) <= 1e-8
    return [fixed_literal(c, QUAT_DECIMALS) for c in r]


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
    if len(vals) > 6 or any(as_float(v) is None or not math.isfinite(as_float(v)) for v in vals):
        raise ValueError(f"external_axes for {target_id!r}: expected at most 6 finite numbers, got {vals!r}")
    return [fixed_literal(v, JOINT_DECIMALS) for v in vals] + [RAPID_UNUSED] * (6 - len(vals))



def _rapid_header(module_name: str, n: int, persistent: bool, with_error: bool) -> list[str]:
    """The comment block at the top of the module (deterministic: no date)."""
    kind = "PERS" if persistent else "CONST"
    if with_error:
        error = ["    !   err_cal_mm{i}  predicted position error (mm):",
                 *("    !                  " + line for line in textwrap.wrap(PREDICTED_ERROR_METHOD, 66))]
    else:
        error = ["    ! No err_cal_mm array: the predicted position error is unknown (no held-out",
                 "    ! figures of the model beside it)."]
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
        *error,
        f"    ! Data are {kind}; unused external axes are 9E9.  Do not edit by hand.",
        "    !" + "*" * 70,
    ]


def _chain_axes(t: CorrectedTarget, axes: AbbAxes) -> tuple[list[float], list[float], list[float]]:
    """(robax, jointtarget extax, robtarget extax) of a target: a track's carriage in both (mm); a seven-axis arm's
    axis 7 in the jointtarget, its arm angle in the robtarget (deg)."""
    if axes.layout == "arm" and axes.n < 6:
        raise ValueError(f"RAPID write-back of a {axes.n}-axis arm: the jointtarget layout of ABB's arms with fewer "
                         "than six axes is not known here (use the CSV)")
    rob, ext = axes.split(t.q_corrected_deg)
    if axes.layout != "seven":
        return rob, ext, ext
    if not math.isfinite(t.arm_angle_deg):
        raise ValueError(f"target {t.target_id!r}: a seven-axis robtarget needs the arm angle")
    return rob, ext, [t.arm_angle_deg]


def _axes_note(axes: AbbAxes) -> list[str]:
    """Header lines saying what eax_a holds for a chain that uses it."""
    if axes.layout == "track":
        return ["    ! eax_a: the track's carriage position (mm), the same in jt_cal and rt_cal."]
    if axes.layout == "seven":
        return ["    ! Seven-axis arm: jt_cal eax_a = axis 7 (deg); rt_cal eax_a = the arm angle (deg),",
                "    ! as docs/chains.md defines it (check it against the controller's before a MoveL)."]
    return []


def render_rapid_module(targets: Iterable[CorrectedTarget], *, module_name: str = "CalTargets",
                        persistent: bool = False, q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                        external_axes: Sequence[float] | Mapping[str, Sequence[float]] | None = None,
                        axes: AbbAxes | None = None) -> str:
    """Text of the RAPID module for ``targets`` (see :func:`write_rapid_module`)."""
    axes = axes_layout(6) if axes is None else axes
    items = require_writable(targets, q_min_deg, q_max_deg, n_joints=axes.n, allow_empty=False)
    if axes.external and external_axes is not None:
        raise ValueError("external_axes: this chain's own external axis is eax_a (a track or axis 7)")
    problem = rapid_ident_problem(module_name)
    if problem:
        raise ValueError(f"module_name: {problem}")
    storage = "PERS" if persistent else "CONST"
    jt, rt, ids, err = [], [], [], []
    for t in items:
        rob, jext, rext = _chain_axes(t, axes)
        ext = rapid_aggregate(_rapid_extax(external_axes if not axes.external else jext, t.target_id))
        joints = rapid_aggregate(fixed_literal(q, JOINT_DECIMALS) for q in rob)
        jt.append(rapid_aggregate([joints, ext]))
        pos = rapid_aggregate(fixed_literal(p, POSITION_DECIMALS) for p in t.p_command_base_mm)
        conf = rapid_aggregate(str(int(c)) for c in t.confdata)
        rext = ext if not axes.external else rapid_aggregate(_rapid_extax(rext, t.target_id))
        rt.append(rapid_aggregate([pos, rapid_aggregate(_rapid_quat(t.quat_command_wxyz)), conf, rext]))
        ids.append(rapid_string(t.target_id))
        e = float(t.predicted_error_mm)
        err.append(fixed_literal(e, ERROR_DECIMALS) if math.isfinite(e) else None)
    with_error = all(e is not None for e in err)
    lines = [f"MODULE {module_name}", *_rapid_header(module_name, len(items), persistent, with_error),
             *_axes_note(axes), "",
             "    ! Number of targets.", f"    CONST num n_cal:={len(items)};",
             "    ! Source target ids.", *rapid_array_lines(storage, "string", "id_cal", ids),
             "    ! Corrected joints (deg).", *rapid_array_lines(storage, "jointtarget", "jt_cal", jt),
             "    ! Command poses (mm, quaternion w-first, base frame).",
             *rapid_array_lines(storage, "robtarget", "rt_cal", rt),
             *(["    ! Predicted position errors (mm).", *rapid_array_lines(storage, "num", "err_cal_mm", err)]
               if with_error else []),
             "ENDMODULE", ""]
    text = "\n".join(lines)
    errors = check_rapid_syntax(text, max_line_len=RAPID_MAX_LINE_ID)
    if errors:  # pragma: no cover - a writer bug; never write an unchecked module
        raise ValueError(f"generated RAPID module is invalid: {errors[0]}")
    return text


def write_rapid_module(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                       module_name: str = "CalTargets", persistent: bool = False,
                       q_min_deg: Sequence[float], q_max_deg: Sequence[float],
                       external_axes: Sequence[float] | Mapping[str, Sequence[float]] | None = None,
                       axes: AbbAxes | None = None) -> Path:
    """Write an ABB RAPID module of the accepted targets atomically; return the path. ``axes``
    (``drivers.abb_axes``, default a 6-axis arm): how the chain's joints map onto robax/extax.

    Arrays ``id_cal{N}`` (string), ``jt_cal{N}`` (jointtarget, deg, 6 decimals),
    ``rt_cal{N}`` (robtarget: mm 4 decimals, quaternion 9 decimals, confdata),
    ``err_cal_mm{N}`` (num, mm: predicted position error; left out when a
    target's is unknown) and ``CONST num n_cal``; ``CONST`` data, or
    ``PERS`` when ``persistent``.  ``external_axes``: None (all ``9E9``), up to
    6 values (deg or mm) for every target, or a mapping target id -> values.
    Raises ValueError, writing nothing, for an invalid target or one outside
    ``[q_min_deg, q_max_deg]``, ids over 80 characters or not ISO 8859-1.
    """
    text = render_rapid_module(targets, module_name=module_name, persistent=persistent,
                               q_min_deg=q_min_deg, q_max_deg=q_max_deg, external_axes=external_axes, axes=axes)
    return atomic_write(path, text.encode("ascii"))
