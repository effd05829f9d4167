"""RAPID lexer: the data-type table, token and node records, and the tokenizer (see ``parser``)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from .literals import RAPID_MAX_IDENT, RAPID_MAX_STRING

# Structure of the known data types: an atomic kind ("num", "bool", "string"),
# a tuple of (component, type) pairs, or None (opaque: no initialiser check).
RAPID_TYPES: dict[str, Any] = {
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
MODULE_ATTRS = frozenset({"SYSMODULE", "NOVIEW", "NOSTEPIN", "VIEWONLY", "READONLY"})
DECL_WORDS = frozenset({"CONST", "PERS", "VAR"})
ROUTINE_END = {"PROC": "ENDPROC", "FUNC": "ENDFUNC", "TRAP": "ENDTRAP"}
END_WORDS = frozenset({"ENDIF", "ENDFOR", "ENDWHILE", "ENDTEST", "ENDPROC", "ENDFUNC", "ENDTRAP",
                        "ENDMODULE", "ENDRECORD"})
MODULE_LEVEL = frozenset({"CONST", "PERS", "VAR", "LOCAL", "TASK", "PROC", "FUNC", "TRAP", "RECORD",
                           "ALIAS", "ENDMODULE", "MODULE"})
STATEMENT_WORDS = END_WORDS | {"IF", "ELSEIF", "ELSE", "FOR", "WHILE", "TEST", "CASE", "DEFAULT",
                                 "ERROR", "UNDO", "BACKWARD"} | MODULE_LEVEL
CONTINUE_WORDS = frozenset({"AND", "OR", "XOR", "NOT", "DIV", "MOD", "THEN", "DO", "TO", "FROM", "STEP"})
BINOPS = frozenset({"+", "-", "*", "/", "<", "<=", ">", ">=", "=", "<>", "DIV", "MOD", "AND", "OR", "XOR"})
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
class Tok:
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
class Lit:
    value: Any
    kind: str  # "num", "bool", "string"
    line: int
    text: str


@dataclass
class Agg:
    items: list
    line: int


@dataclass
class Expr:
    text: str
    line: int


@dataclass
class Decl:
    storage: str
    type_name: str
    name: str
    dims: tuple
    value: Any
    line: int


class ParseError(Exception):
    def __init__(self, line: int, message: str) -> None:
        super().__init__(message)
        self.line = line
        self.message = message


def strip_percent_header(text: str) -> str:
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


def tokenize(text: str, errors: list[tuple[int, str]]) -> list[Tok]:
    """RAPID tokens of ``text``; lexical errors go to ``errors`` as (line, message)."""
    toks: list[Tok] = []
    i, line, first, comment = 0, 1, True, False

    def add(kind: str, s: str, value: Any = None) -> None:
        nonlocal first, comment
        toks.append(Tok(kind, s, line, value, first, comment))
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
    toks.append(Tok("eof", "end of file", line, None, True, comment))
    return toks
