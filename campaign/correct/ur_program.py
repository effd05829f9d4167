"""Universal Robots joint targets: JSON and URScript, and the URScript checker."""

from __future__ import annotations

import json
import math
import os
import re
import textwrap
from pathlib import Path
from typing import Iterable, Sequence

from drivers.rapid.literals import fixed_literal

from campaign.io.durable import atomic_write
from .accuracy import PREDICTED_ERROR_METHOD
from .bounds import (GENERATOR, ERROR_DECIMALS, UR_JSON_FORMAT, UR_MAX_A_RAD_S2, UR_MAX_V_RAD_S, UR_RAD_DECIMALS,
                     URSCRIPT_FORMAT, CorrectedTarget, as_float, require_writable)

def render_ur_json(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                   q_max_deg: Sequence[float]) -> str:
    """Text of the UR joint-targets JSON (see :func:`write_ur_json`)."""
    items = require_writable(targets, q_min_deg, q_max_deg, n_joints=6)
    doc = {
        "format": UR_JSON_FORMAT,
        "units": {"q": "rad", "predicted_error": "mm", "predicted_std": "mm", "solver_tolerance": "mm"},
        "predicted_error_method": PREDICTED_ERROR_METHOD,
        "targets": [{
            "id": t.target_id,
            "q_rad": [math.radians(float(q)) for q in t.q_corrected_deg],
            "q_deg": [float(q) for q in t.q_corrected_deg],
            "q_nominal_rad": [math.radians(float(q)) for q in t.q_nominal_deg],
            "predicted_error_mm": _number_or_null(t.predicted_error_mm),
            "predicted_std_mm": _number_or_null(t.predicted_std_mm),
            "solver_tolerance_mm": float(t.solver_tolerance_mm),
        } for t in items],
    }
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def _number_or_null(x: float) -> float | None:
    """A finite float, or None (JSON null) for nan: unknown or not applicable."""
    return None if math.isnan(float(x)) else float(x)


def write_ur_json(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                  q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> Path:
    """Write the accepted targets (6 joints) as UR JSON atomically; return the path.

    ``{"format": "ur-joint-targets/2", "units": {...}, "predicted_error_method",
    "targets": [{"id", "q_rad", "q_deg", "q_nominal_rad", "predicted_error_mm",
    "predicted_std_mm", "solver_tolerance_mm"}]}``; angles in rad (``q_deg`` in
    deg), full float precision, null for an unknown predicted error or std.  ValueError, writing
    nothing, for an invalid target or one outside ``[q_min_deg, q_max_deg]``.
    """
    return atomic_write(path, render_ur_json(targets, q_min_deg=q_min_deg, q_max_deg=q_max_deg).encode("ascii"))


_UR_KEYWORDS = frozenset({"def", "end", "if", "elif", "else", "while", "for", "thread", "return", "break",
                          "continue", "global", "local", "True", "False", "not", "and", "or", "xor", "run",
                          "kill", "join", "halt", "sec", "enter_critical", "exit_critical"})
_UR_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _ur_motion_bound(value: float, name: str, upper: float) -> float:
    """A URScript speed/acceleration in (0, upper]; ValueError otherwise."""
    v = as_float(value)
    if v is None or not math.isfinite(v) or not 0 < v <= upper:
        raise ValueError(f"{name}: expected a number in (0, {upper:g}], got {value!r}")
    return v


def render_urscript(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                    q_max_deg: Sequence[float], a_rad_s2: float = 0.5, v_rad_s: float = 0.3,
                    name: str = "cal_targets") -> str:
    """Text of the URScript program (see :func:`write_urscript`)."""
    items = require_writable(targets, q_min_deg, q_max_deg, n_joints=6, allow_empty=False)
    a = _ur_motion_bound(a_rad_s2, "a_rad_s2", UR_MAX_A_RAD_S2)
    v = _ur_motion_bound(v_rad_s, "v_rad_s", UR_MAX_V_RAD_S)
    if not _UR_NAME_RE.match(name) or name in _UR_KEYWORDS:
        raise ValueError(f"name: {name!r} is not a URScript function name")
    lines = [f"# {name}: {len(items)} corrected targets, written by {GENERATOR} ({URSCRIPT_FORMAT}).",
             "# Joints in rad; each target: '# <target id> predicted_error_mm=<mm or unknown>' then movej.",
             *("# " + line for line in textwrap.wrap("predicted_error_mm: " + PREDICTED_ERROR_METHOD + ".", 96)),
             "# Only targets that passed the safety bounds are here.",
             f"def {name}():"]
    for t in items:
        q = ",".join(fixed_literal(math.radians(float(x)), UR_RAD_DECIMALS) for x in t.q_corrected_deg)
        e = float(t.predicted_error_mm)
        error = fixed_literal(e, ERROR_DECIMALS) if math.isfinite(e) else "unknown"
        lines.append(f"  # {t.target_id} predicted_error_mm={error}")
        lines.append(f"  movej([{q}], a={fixed_literal(a, 6)}, v={fixed_literal(v, 6)})")
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
    target, preceded by ``# <id> predicted_error_mm=<mm or unknown>``.  ValueError,
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
