"""RAPID data as the controller holds it: literals parsed to nested lists, rendered back as RobotWare prints them,
and a light module reader (name, main, routines, module-level data) -- the model the RWS emulator runs on.
The strict module checker is ``parser``; both share the type table in ``lexer``."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from .lexer import _RAPID_TYPES

class RapidSyntaxError(ValueError):
    """A RAPID literal or module that does not parse."""


_TOKEN = re.compile(r'\s*(?:(?P<open>\[)|(?P<close>\])|(?P<comma>,)|(?P<str>"(?:[^"]|"")*")'
                    r'|(?P<bool>TRUE\b|FALSE\b)|(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?))', re.I)


def parse_literal(text: str) -> Any:
    """RAPID literal -> nested lists of float / str / bool (aggregates are lists)."""
    value, pos = _parse_value(text, 0)
    if text[pos:].strip():
        raise RapidSyntaxError(f"trailing text after literal: {text[pos:pos + 20]!r}")
    return value


def _parse_value(text: str, pos: int) -> tuple[Any, int]:
    m = _TOKEN.match(text, pos)
    if not m or m.lastgroup in ("close", "comma"):
        raise RapidSyntaxError(f"unexpected text at {pos}: {text[pos:pos + 20]!r}")
    if m.lastgroup == "num":
        return float(m.group("num")), m.end()
    if m.lastgroup == "str":
        return m.group("str")[1:-1].replace('""', '"'), m.end()
    if m.lastgroup == "bool":
        return m.group("bool").upper() == "TRUE", m.end()
    items, pos = [], m.end()
    while True:
        item, pos = _parse_value(text, pos)
        items.append(item)
        m = _TOKEN.match(text, pos)
        if m and m.lastgroup == "comma":
            pos = m.end()
        elif m and m.lastgroup == "close":
            return items, m.end()
        else:
            raise RapidSyntaxError(f"expected ',' or ']' at {pos}")


N, S, B = "num", "string", "bool"
def _shape(type_name: str) -> Any:
    """Literal shape of a type of the shared table: "num"/"string"/"bool" or a list of component shapes."""
    spec = _RAPID_TYPES[type_name]
    return spec if isinstance(spec, str) else [_shape(component) for _, component in spec]


# the types whose initial values the emulator checks
SHAPES: dict[str, Any] = {name: _shape(name) for name in (
    "num", "dnum", "bool", "string", "speeddata", "pos", "orient", "confdata", "robjoint", "extjoint", "jointtarget",
    "robtarget", "pose", "loaddata", "tooldata")}


def matches(value: Any, shape: Any) -> bool:
    """Whether a parsed literal has the shape of a RAPID type (``SHAPES``)."""
    if shape == N:
        return isinstance(value, float)
    if shape == S:
        return isinstance(value, str)
    if shape == B:
        return isinstance(value, bool)
    return isinstance(value, list) and len(value) == len(shape) and all(map(matches, value, shape))


def render(value: Any) -> str:
    """A parsed literal as the controller prints it: single precision, ``9E+09``, quoted strings."""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        if abs(value) >= 1e9:
            return "9E+09" if value > 0 else "-9E+09"
        text = f"{value:.7g}".replace("e", "E")
        return "0" if text == "-0" else text
    if isinstance(value, str):
        return '"' + value.replace('"', '""') + '"'
    return "[" + ",".join(render(v) for v in value) + "]"


@dataclass
class Symbol:
    """A module-level RAPID data declaration; ``value`` is the rendered literal."""
    module: str
    name: str
    storage: str        # PERS, VAR, CONST
    dtype: str
    value: str
    array: bool = False


@dataclass
class Module:
    name: str
    text: str
    symbols: dict[str, Symbol]
    has_main: bool
    routines: dict[str, str] = field(default_factory=dict)   # lower-case PROC name -> its parameter text
    main_calls: frozenset[str] = frozenset()                  # lower-case procedures main calls without arguments

    def calls(self, routine: str, callee: str) -> bool:
        """Whether PROC ``routine`` of this module calls ``callee`` (a procedure call statement)."""
        code = _strip_comments(self.text)
        m = re.search(rf"^\s*(?:LOCAL\s+)?PROC\s+{routine}\s*\(.*?^\s*ENDPROC\b", code, re.I | re.M | re.S)
        return bool(m and re.search(rf"^\s*{callee}\s*;", m.group(0), re.I | re.M))


_ROUTINE = re.compile(r"^\s*(?:LOCAL\s+)?(PROC|FUNC|TRAP)\b.*?^\s*END(?:PROC|FUNC|TRAP)\b", re.I | re.M | re.S)
_DECL = re.compile(r"^\s*(?:LOCAL\s+|TASK\s+)?(PERS|VAR|CONST)\s+(\w+)\s+(\w+)\s*(\{[^}]*\})?\s*(?::=\s*(.*?))?;",
                   re.I | re.M | re.S)


def _strip_comments(text: str) -> str:
    """Remove ``!`` comments (outside string literals)."""
    out = []
    for line in text.splitlines():
        quoted = False
        for i, ch in enumerate(line):
            if ch == '"':
                quoted = not quoted
            elif ch == "!" and not quoted:
                line = line[:i]
                break
        out.append(line)
    return "\n".join(out)


def parse_module(text: str) -> Module:
    """Parse a module's name, ``main`` and module-level data declarations (types checked for known types)."""
    code = _strip_comments(text)
    head = re.match(r"\s*MODULE\s+([A-Za-z]\w*)", code, re.I)
    if not head or not re.search(r"^\s*ENDMODULE\b", code, re.I | re.M):
        raise RapidSyntaxError("not a RAPID module (MODULE name ... ENDMODULE)")
    has_main = bool(re.search(r"^\s*PROC\s+main\s*\(\s*\)", code, re.I | re.M))
    routines = {name.lower(): params.strip() for name, params in
                re.findall(r"^\s*(?:LOCAL\s+)?PROC\s+(\w+)\s*\(([^)]*)\)", code, re.I | re.M)}
    data = _ROUTINE.sub("", code)
    symbols = {}
    for storage, dtype, name, dims, init in _DECL.findall(data):
        value = _initial_value(dtype, init, bool(dims), name)
        symbols[name.lower()] = Symbol(head.group(1), name, storage.upper(), dtype.lower(), value, bool(dims))
    main = re.search(r"^\s*PROC\s+main\s*\(\s*\).*?^\s*ENDPROC\b", code, re.I | re.M | re.S)
    calls = frozenset(c.lower() for c in re.findall(r"^\s*(\w+)\s*;", main.group(0), re.M)) if main else frozenset()
    return Module(head.group(1), text, symbols, has_main, routines, calls - RAPID_KEYWORDS)


RAPID_KEYWORDS = frozenset({"stop", "exit", "return", "break", "endproc", "endwhile", "endif", "endfor", "endtest",
                            "else", "retry", "trynext"})

def _initial_value(dtype: str, init: str, array: bool, name: str) -> str:
    """Rendered initial value; zero/empty default when a VAR has no initialiser."""
    shape = SHAPES.get(dtype.lower())
    if not init.strip():
        return render(_zero(shape)) if shape is not None and not array else "[]"
    value = parse_literal(init)
    if shape is not None and not array and not matches(value, shape):
        raise RapidSyntaxError(f"initial value of {name} is not a {dtype}")
    return render(value)


def _zero(shape: Any) -> Any:
    if shape == N:
        return 0.0
    if shape == S:
        return ""
    if shape == B:
        return False
    return [_zero(s) for s in shape]
