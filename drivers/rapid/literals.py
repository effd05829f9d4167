"""RAPID literals and layout: identifiers, strings, numbers, aggregates wrapped to the line limit.

Pure text functions shared by the target writer (``campaign.correct.rapid_module``) and the ABB driver.
"""

from __future__ import annotations

import math
import re
from typing import Iterable, Sequence

from drivers.base import DriverError

RAPID_MAX_LINE = 100      # longest line the RAPID writer emits (characters) ...
RAPID_MAX_STRING = 80     # RAPID string data: at most 80 characters
RAPID_MAX_LINE_ID = 8 + 3 * RAPID_MAX_STRING + 3  # ... except an id line full of \\hh escapes (251)
RAPID_MAX_IDENT = 32      # RAPID identifiers: at most 32 characters
RAPID_UNUSED = "9E9"      # value of an unused external axis
RAPID_UNUSED_AXIS = 9e9   # the same as a number


def fixed_literal(x: float, decimals: int) -> str:
    """``x`` with ``decimals`` decimals, trailing zeros dropped, never ``-0`` (RAPID/URScript literal)."""
    s = f"{float(x):.{decimals}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s



RAPID_RESERVED = frozenset("""
ALIAS AND BACKWARD CASE CONNECT CONST DEFAULT DIV DO ELSE ELSEIF ENDFOR ENDFUNC ENDIF ENDMODULE
ENDPROC ENDRECORD ENDTEST ENDTRAP ENDWHILE ERROR EXIT FALSE FOR FROM FUNC GOTO IF INOUT LOCAL MOD
MODULE NOSTEPIN NOT NOVIEW OR PERS PROC RAISE READONLY RECORD RETRY RETURN STEP SYSMODULE TASK TEST
THEN TO TRAP TRUE TRYNEXT UNDO VAR VIEWONLY WHILE WITH XOR""".split())
_RAPID_IDENT_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def rapid_ident_problem(name: str) -> str | None:
    """Why ``name`` is not a RAPID identifier (None when it is)."""
    if not _RAPID_IDENT_RE.match(name):
        return f"bad identifier '{name}': a letter, then letters, digits or '_'"
    if len(name) > RAPID_MAX_IDENT:
        return f"identifier '{name}' is longer than {RAPID_MAX_IDENT} characters"
    if name.upper() in RAPID_RESERVED:
        return f"'{name}' is a reserved word"
    return None


def rapid_string(text: str) -> str:
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



def rapid_aggregate(parts: Iterable[str]) -> str:
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


def rapid_array_lines(storage: str, type_name: str, name: str, elements: Sequence[str]) -> list[str]:
    """Lines of ``STORAGE type name{N}:=[e1, ..., eN];``, one element per line (wrapped)."""
    lines = [f"    {storage} {type_name} {name}{{{len(elements)}}}:=["]
    for k, element in enumerate(elements):
        lines += _wrap(element + ("," if k < len(elements) - 1 else ""), " " * 8)
    lines.append("    ];")
    return lines


# --------------------------------------------------------------------------- data values over RWS (ABB driver)


def fmt_num(value: float) -> str:
    """RAPID num literal: fixed point, at most 6 decimals, ``9E9`` for unused axes, no ``-0``."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {value}")
    if abs(value) >= 1e9:
        return "9E9" if value > 0 else "-9E9"
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def fmt_jointtarget(q_deg: Sequence[float], ext: Sequence[float] = ()) -> str:
    """``[[j1..j6],[e1..e6]]`` (deg); missing robot axes are 0, missing external axes 9E9."""
    rob = list(q_deg) + [0.0] * (6 - len(q_deg))
    eax = list(ext) + [RAPID_UNUSED_AXIS] * (6 - len(ext))
    return f"[[{','.join(fmt_num(v) for v in rob)}],[{','.join(fmt_num(v) for v in eax)}]]"


def fmt_robtarget(trans_mm: Sequence[float], quat_wxyz: Sequence[float], conf: Sequence[int] = (0, 0, 0, 0),
                  ext: Sequence[float] = ()) -> str:
    """``[[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[e1..e6]]`` with the quaternion normalised (w first); external axes
    ``ext`` (a track in mm, a seven-axis arm's arm angle in deg), the others 9E9."""
    norm = math.sqrt(sum(float(q) ** 2 for q in quat_wxyz))
    if len(trans_mm) != 3 or len(quat_wxyz) != 4 or len(conf) != 4 or not norm > 0:
        raise ValueError("robtarget needs xyz (3), a non-zero quaternion (4) and confdata (4)")
    quat = [float(q) / norm for q in quat_wxyz]
    eax = list(ext) + [RAPID_UNUSED_AXIS] * (6 - len(ext))
    parts = [",".join(fmt_num(v) for v in trans_mm), ",".join(fmt_num(v) for v in quat),
             ",".join(str(int(c)) for c in conf), ",".join(fmt_num(v) for v in eax)]
    return "[" + ",".join(f"[{p}]" for p in parts) + "]"


def fmt_string(text: str) -> str:
    """RAPID string literal with the quotes (``"`` and ``\\`` doubled as RAPID requires)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '""') + '"'


def parse_string(literal: str) -> str:
    """Inverse of ``fmt_string``; tolerates a value without quotes."""
    text = literal.strip()
    if len(text) >= 2 and text[0] == text[-1] == '"':
        text = text[1:-1].replace('""', '"').replace("\\\\", "\\")
    return text


def parse_num(literal: str) -> float:
    """A RAPID num literal (``12``, ``-0.5``, ``9E+09``)."""
    try:
        return float(literal.strip())
    except ValueError as exc:
        raise DriverError(f"not a RAPID num: {literal[:40]!r}") from exc
