"""RAPID parser, second level: data declarations (module level and inside routines), routines and their
statements (nested IF/FOR/WHILE/TEST blocks, error handlers, labels, ``;``), and recovery after an error
(``sync``). Builds on :mod:`.expressions`; the module level is in :mod:`.parser`."""

from __future__ import annotations

from typing import Any, Iterable

from .expressions import ExpressionParser
from .lexer import CONTINUE_WORDS, DECL_WORDS, END_WORDS, MODULE_LEVEL, ROUTINE_END, STATEMENT_WORDS, Decl, \
    ParseError, Tok
from .literals import RAPID_RESERVED, rapid_ident_problem


class StatementParser(ExpressionParser):
    """Declarations, routines and statements; module-level declarations are kept in ``decls``, procedures (with
    the procedures they call without arguments) in ``procs`` and ``proc_calls``."""

    def __init__(self, text: str, extra_types: Iterable[str] = ()) -> None:
        super().__init__(text, extra_types)
        self.decls: dict[str, Decl] = {}
        self.procs: dict[str, str] = {}               # lower-case PROC name -> its parameter text
        self.proc_calls: dict[str, set[str]] = {}     # lower-case PROC name -> procedures it calls without arguments
        self.proc: str | None = None                  # the PROC being read

    def sync(self, module_level: bool) -> None:
        """Skip to after the next ';', or to the next line that starts a module item (or any line)."""
        self.in_stmt = False
        while self.peek().kind != "eof":
            tok = self.peek()
            if tok.kind == "op" and tok.text == ";":
                self.next()
                return
            if tok.first and (tok.up in MODULE_LEVEL or not module_level):
                return
            self.next()

    def type_name(self) -> str:
        tok = self.name("data type")
        if tok.text.lower() not in self.types:
            raise ParseError(tok.line, f"unknown data type '{tok.text}'")
        return tok.text.lower()

    # -- declarations
    def declaration(self, module_level: bool) -> None:
        start = self.next()
        try:
            self.in_stmt = True
            storage = self.next().up if start.up in ("LOCAL", "TASK") else start.up
            if storage == "PERS" and not module_level:
                raise ParseError(start.line, "PERS data must be declared at module level")
            type_name = self.type_name()
            name = self.name("data name")
            dims = self.dimensions() if self.is_op("{") else ()
            value = None
            if self.is_op(":="):
                self.next()
                value = self.expression()
            elif storage == "CONST":
                raise ParseError(name.line, f"CONST {name.text} needs an initial value ':='")
            tok = self.peek()
            if not (tok.kind == "op" and tok.text == ";"):
                raise ParseError(self.toks[self.i - 1].line, f"missing ';' after the declaration of "
                                                              f"'{name.text}' (got '{tok.text}')")
            self.next()
            self.in_stmt = False
        except ParseError as e:
            self.err(e.line, e.message)
            self.sync(module_level)
            return
        decl = Decl(storage, type_name, name.text, dims, value, start.line)
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
                raise ParseError(tok.line, f"array dimension must be an integer > 0, got '{tok.text}'")
            if self.is_op("}"):
                self.next()
                break
            self.expect_op(",", "between array dimensions")
        if len(dims) > 3:
            raise ParseError(tok.line, "arrays have at most 3 dimensions")
        return tuple(dims)

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

    def body(self, kind: str, name: Tok) -> None:
        """Statements up to the routine's END word, checking nested blocks and ';'."""
        stack = [(ROUTINE_END[kind], f"{kind} {name.text}", name.line)]
        while stack:
            tok, before = self.peek(), self.i
            try:
                if tok.kind == "eof" or tok.up in MODULE_LEVEL - DECL_WORDS - {"LOCAL"}:
                    for end, opener, line in reversed(stack):
                        self.err(line, f"missing {end} for {opener} (line {line})")
                    return
                if tok.up in DECL_WORDS or tok.up == "LOCAL":
                    self.declaration(module_level=False)
                elif tok.up in END_WORDS:
                    self.close_block(stack)
                else:
                    self.statement(stack)
            except ParseError as e:
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
                raise ParseError(tok.line, f"{up} outside IF ... ENDIF")
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
                raise ParseError(tok.line, f"{up} outside TEST ... ENDTEST")
            self.scan({":"}, tok)
        elif up in ("ERROR", "UNDO", "BACKWARD"):
            if len(stack) != 1:
                raise ParseError(tok.line, f"{up} handler inside a block: missing {top}?")
            if up == "ERROR" and self.is_op("(") and not self.peek().first:
                self.skip_group(self.next())
        elif tok.kind == "op" and tok.text == ";":
            raise ParseError(tok.line, "empty statement ';'")
        elif tok.kind == "id" and self.is_op(":") and tok.up not in RAPID_RESERVED:
            self.next()  # a label
        else:
            if tok.kind == "id" and self.is_op(";") and self.proc is not None:
                self.proc_calls[self.proc].add(tok.text.lower())     # a call without arguments
            self.scan({";"}, tok, first=tok)

    def scan(self, terminators: set[str], start: Tok, consume: bool = True, first: Tok | None = None) -> str:
        """Consume a statement up to one of ``terminators`` at bracket depth 0; return it.

        ``first``: the statement's first token when already consumed.
        """
        pairs = {"(": ")", "[": "]", "{": "}"}
        stack: list[Tok] = [first] if first is not None and first.kind == "op" and first.text in pairs else []
        prev: Tok | None = first
        self.in_stmt = True
        try:
            while True:
                tok = self.peek()
                word = tok.up or (tok.text if tok.kind == "op" else "")
                if tok.kind == "eof":
                    raise ParseError(start.line, f"statement of line {start.line} is not terminated")
                if not stack:
                    if word in terminators:
                        if consume:
                            self.next()
                        return word
                    if prev is not None and tok.first and self._line_break_ends(prev, tok):
                        want = " or ".join(sorted(f"'{t}'" for t in terminators))
                        raise ParseError(prev.line, f"missing {want} at the end of the line")
                elif tok.kind == "op" and tok.text == ";":
                    raise ParseError(tok.line, f"unbalanced brackets: '{stack[-1].text}' of line "
                                                f"{stack[-1].line} is not closed")
                if tok.kind == "op" and tok.text in pairs:
                    stack.append(tok)
                elif tok.kind == "op" and tok.text in ")]}":
                    if not stack or pairs[stack[-1].text] != tok.text:
                        raise ParseError(tok.line, f"unbalanced brackets: unexpected '{tok.text}'")
                    stack.pop()
                prev = self.next()
        finally:
            self.in_stmt = False

    @staticmethod
    def _line_break_ends(prev: Tok, tok: Tok) -> bool:
        """True when ``tok`` (first on its line) cannot continue the statement ending with ``prev``."""
        if tok.up in STATEMENT_WORDS:
            return True
        ends_value = prev.kind in ("num", "str") or (prev.kind == "id" and prev.up not in CONTINUE_WORDS) \
            or (prev.kind == "op" and prev.text in ")]}")
        return ends_value and tok.kind == "id" and tok.up not in CONTINUE_WORDS
