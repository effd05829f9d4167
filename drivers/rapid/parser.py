"""RAPID module checker and reader: :func:`check_rapid_syntax` and :func:`parse_rapid_module`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

from .lexer import (_BINOPS, _CONTINUE_WORDS, _DECL_WORDS, _END_WORDS, _MODULE_ATTRS, _MODULE_LEVEL, _RAPID_TYPES,
                    _ROUTINE_END, _STATEMENT_WORDS, RapidExpr, _Agg, _Decl, _Expr, _Lit, _ParseError, _strip_percent_header,
                    _Tok, _tokenize)
from .literals import _RAPID_RESERVED, rapid_ident_problem

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
        self.module_name = ""
        self.procs: dict[str, str] = {}               # lower-case PROC name -> its parameter text
        self.proc_calls: dict[str, set[str]] = {}     # lower-case PROC name -> procedures it calls without arguments
        self.proc: str | None = None                  # the PROC being read

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
            self.module_name = name.text
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
            elif tok.kind == "id" and not rapid_ident_problem(tok.text):
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
        params = ""
        if kw.up != "TRAP":
            open_tok, start = self.expect_op("(", f"after {kw.up} {name.text}"), self.i
            self.skip_group(open_tok)
            params = " ".join(t.text for t in self.toks[start:self.i - 1])
        if kw.up == "PROC":
            self.proc = name.text.lower()
            self.procs[self.proc], self.proc_calls[self.proc] = params, set()
        try:
            self.body(kw.up, name)
        finally:
            self.proc = None

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
            if tok.kind == "id" and self.is_op(";") and self.proc is not None:
                self.proc_calls[self.proc].add(tok.text.lower())     # a call without arguments
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
            raise _ParseError(parser.peek().line, f"text after the literal: '{parser.peek().text}'")
    except _ParseError as e:
        parser.err(e.line, e.message)
    errors = _messages(parser)
    if errors:
        raise ValueError(f"RAPID syntax errors: {'; '.join(errors)}")
    value = _to_python(node)
    if _has_expr(value):
        raise ValueError(f"not a RAPID literal: {text.strip()[:40]!r}")
    return value


def _has_expr(value: Any) -> bool:
    return isinstance(value, RapidExpr) or (isinstance(value, list) and any(map(_has_expr, value)))
