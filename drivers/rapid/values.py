"""RAPID data as the controller holds it: literals parsed to nested lists, rendered back as RobotWare prints them,
and the module model (name, main, routines, module-level data) the RWS emulator runs on. Reading goes through the
strict lexer and parser (``parser``), so the emulator refuses what the write-back checker refuses."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .lexer import RAPID_TYPES
from .parser import has_expr, parse_rapid_literal, read_rapid_module


class RapidSyntaxError(ValueError):
    """A RAPID literal or module that does not parse."""


def parse_literal(text: str) -> Any:
    """RAPID literal -> nested lists of float / str / bool (aggregates are lists); read by the strict parser."""
    try:
        return _as_num(parse_rapid_literal(text))
    except ValueError as exc:
        raise RapidSyntaxError(str(exc)) from None


def _as_num(value: Any) -> Any:
    """Integer literals as float (the controller holds num as float); bool, str and lists as they are."""
    if isinstance(value, list):
        return [_as_num(v) for v in value]
    return float(value) if isinstance(value, int) and not isinstance(value, bool) else value


N, S, B = "num", "string", "bool"
def _shape(type_name: str) -> Any:
    """Literal shape of a type of the shared table: "num"/"string"/"bool" or a list of component shapes."""
    spec = RAPID_TYPES[type_name]
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


def parse_module(text: str) -> Module:
    """A module as the controller loads it: the strict checker (``parser``) must pass; then its name, ``main``,
    procedures and module-level data (initial values rendered; zero/empty when a VAR has none)."""
    try:
        outline = read_rapid_module(text)
    except ValueError as exc:
        raise RapidSyntaxError(str(exc)) from None
    symbols = {}
    for storage, dtype, name, dims, init in outline.data:
        value = _initial_value(dtype, init, bool(dims), name)
        symbols[name.lower()] = Symbol(outline.name, name, storage, dtype, value, bool(dims))
    has_main = outline.procs.get("main") == ""
    calls = outline.proc_calls.get("main", frozenset()) if has_main else frozenset()
    return Module(outline.name, text, symbols, has_main, dict(outline.procs), calls - RAPID_KEYWORDS)


RAPID_KEYWORDS = frozenset({"stop", "exit", "return", "break", "endproc", "endwhile", "endif", "endfor", "endtest",
                            "else", "retry", "trynext"})


def _initial_value(dtype: str, init: Any, array: bool, name: str) -> str:
    """Rendered initial value; zero/empty default when a VAR has no initialiser (types were checked by the parser)."""
    if init is None:
        shape = SHAPES.get(dtype)
        return render(_zero(shape)) if shape is not None and not array else "[]"
    if has_expr(init):
        raise RapidSyntaxError(f"initial value of {name} is not a literal")
    return render(_as_num(init))


def _zero(shape: Any) -> Any:
    if shape == N:
        return 0.0
    if shape == S:
        return ""
    if shape == B:
        return False
    return [_zero(s) for s in shape]
