"""RAPID module checker and reader: :func:`check_rapid_syntax` and :func:`parse_rapid_module`.

The recursive-descent parser follows the grammar in three levels: values (:mod:`.expressions`), declarations,
routines and statements (:mod:`.statements`), and the module (here: ``MODULE name [(attributes)]``, its items,
RECORD and ALIAS, ``ENDMODULE``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

from .lexer import DECL_WORDS, MODULE_ATTRS, MODULE_LEVEL, ROUTINE_END, RapidExpr, Agg, Lit, ParseError, Tok
from .statements import StatementParser


class _RapidParser(StatementParser):
    """Recursive-descent checker of a RAPID module; collects errors and module-level declarations."""

    def __init__(self, text: str, extra_types: Iterable[str] = ()) -> None:
        super().__init__(text, extra_types)
        self.module_name = ""

    # -- module
    def parse_module(self) -> None:
        tok = self.next()
        if tok.up != "MODULE":
            self.err(tok.line, f"expected 'MODULE name' at the start, got '{tok.text}'")
            return
        try:
            name = self.name("module name")
            self.module_name = name.text
            if self.is_op("("):
                self.module_attributes()
        except ParseError as e:
            self.err(e.line, e.message)
            return
        self.module_items(name)
        if self.peek().kind != "eof":
            self.err(self.peek().line, f"text after ENDMODULE: '{self.peek().text}'")

    def module_attributes(self) -> None:
        self.next()
        while True:
            tok = self.next()
            if tok.up not in MODULE_ATTRS:
                raise ParseError(tok.line, f"unknown module attribute '{tok.text}'")
            if self.is_op(")"):
                self.next()
                return
            self.expect_op(",", "between module attributes")

    def module_items(self, module: Tok) -> None:
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
                    if after in ROUTINE_END and up == "LOCAL":
                        self.routine()
                    else:
                        self.declaration(module_level=True)
                elif up in DECL_WORDS:
                    self.declaration(module_level=True)
                elif up in ROUTINE_END:
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
                    raise ParseError(tok.line, f"unexpected '{tok.text}' at module level")
            except ParseError as e:
                self.err(e.line, e.message)
                self.sync(module_level=True)
                if self.i == before:
                    self.next()

    def record(self) -> None:
        start = self.next()
        name = self.name("record name")
        self.types[name.text.lower()] = None
        while self.peek().up != "ENDRECORD":
            if self.peek().kind == "eof" or self.peek().up in MODULE_LEVEL:
                raise ParseError(start.line, f"RECORD {name.text} without ENDRECORD")
            self.type_name()
            self.name("record component")
            self.expect_op(";", "after record component")
        self.next()


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
    if isinstance(node, Agg):
        return [_to_python(item) for item in node.items]
    if isinstance(node, Lit):
        return node.value
    return RapidExpr(node.text)


def parse_rapid_module(text: str, *, extra_types: Iterable[str] = ()) -> dict[str, Any]:
    """Module-level data of a RAPID module: name -> value, in declaration order.

    Values are nested lists of int (integer literals), float, str (decoded
    strings) and bool; a non-literal value is a :class:`RapidExpr`; a
    declaration without initial value maps to None.  Raises ValueError listing
    the syntax errors when :func:`check_rapid_syntax` finds any.
    """
    return {name: value for _, _, name, _, value in read_rapid_module(text, extra_types=extra_types).data}


@dataclass(frozen=True)
class RapidModuleOutline:
    """What a controller keeps of a module that checks: its name, module-level data (``parse_rapid_module``
    values, in declaration order, with storage, type and dimensions) and its procedures."""

    name: str
    data: tuple[tuple[str, str, str, tuple, Any], ...]   # (storage, type, name, dims, value)
    procs: dict[str, str]                                 # lower-case PROC name -> its parameter text
    proc_calls: dict[str, frozenset[str]]                 # lower-case PROC name -> procedures called without arguments


def read_rapid_module(text: str, *, extra_types: Iterable[str] = ()) -> RapidModuleOutline:
    """The outline of a RAPID module; raises ValueError listing the syntax errors (as ``parse_rapid_module``)."""
    parser = _run_rapid_parser(text, None, extra_types)
    errors = _messages(parser)
    if errors:
        raise ValueError(f"RAPID syntax errors: {'; '.join(errors)}")
    data = tuple((d.storage, d.type_name, d.name, d.dims, _to_python(d.value)) for d in parser.decls.values())
    return RapidModuleOutline(parser.module_name, data, dict(parser.procs),
                              {k: frozenset(v) for k, v in parser.proc_calls.items()})


def parse_rapid_literal(text: str) -> Any:
    """A RAPID literal (number, string, TRUE/FALSE, or an aggregate of them) as ``parse_rapid_module`` gives
    values; raises ValueError for a syntax error or a value that is not a literal (a name, an expression)."""
    parser = _RapidParser(text)
    node = None
    try:
        node = parser.expression()
        if parser.peek().kind != "eof":
            raise ParseError(parser.peek().line, f"text after the literal: '{parser.peek().text}'")
    except ParseError as e:
        parser.err(e.line, e.message)
    errors = _messages(parser)
    if errors:
        raise ValueError(f"RAPID syntax errors: {'; '.join(errors)}")
    value = _to_python(node)
    if has_expr(value):
        raise ValueError(f"not a RAPID literal: {text.strip()[:40]!r}")
    return value


def has_expr(value: Any) -> bool:
    return isinstance(value, RapidExpr) or (isinstance(value, list) and any(map(has_expr, value)))
