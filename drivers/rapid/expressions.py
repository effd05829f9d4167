"""RAPID parser, first level: the token stream (access, errors, brackets) and values: expressions, literals,
aggregates, references, and the structure of initial values against the data types (``lexer._RAPID_TYPES``, plus
the module's RECORDs). Built on by :mod:`.statements` and :mod:`.parser`."""

from __future__ import annotations

from typing import Any, Iterable

from .lexer import BINOPS, RAPID_TYPES, Agg, Decl, Expr, Lit, ParseError, strip_percent_header, Tok, tokenize
from .literals import RAPID_RESERVED


class ExpressionParser:
    """Token access and the value grammar of RAPID; collects errors as (line, message)."""

    def __init__(self, text: str, extra_types: Iterable[str] = ()) -> None:
        self.lex_errors: list[tuple[int, str]] = []
        self.errors: list[tuple[int, str]] = []
        self.toks = tokenize(strip_percent_header(text), self.lex_errors)
        self.i = 0
        self.in_stmt = False
        self.types = dict(RAPID_TYPES)
        self.types.update({t.lower(): None for t in extra_types})

    # -- token access
    def peek(self) -> Tok:
        return self.toks[self.i]

    def next(self) -> Tok:
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

    def expect_op(self, text: str, what: str) -> Tok:
        tok = self.peek()
        if tok.kind != "op" or tok.text != text:
            raise ParseError(tok.line, f"expected '{text}' {what}, got '{tok.text}'")
        return self.next()

    def name(self, what: str) -> Tok:
        """An identifier token that may name a declared thing."""
        tok = self.peek()
        if tok.kind != "id":
            raise ParseError(tok.line, f"expected {what}, got '{tok.text}'")
        if tok.up in RAPID_RESERVED:  # form and length are reported by the tokenizer
            raise ParseError(tok.line, f"{what}: '{tok.text}' is a reserved word")
        return self.next()

    def skip_group(self, open_tok: Tok) -> None:
        """Skip to the bracket closing ``open_tok`` (brackets must nest)."""
        pairs = {"(": ")", "[": "]", "{": "}"}
        stack = [open_tok]
        while stack:
            tok = self.next()
            if tok.kind == "eof" or (tok.kind == "op" and tok.text == ";"):
                o = stack[-1]
                raise ParseError(tok.line, f"unbalanced brackets: '{o.text}' of line {o.line} is not closed")
            if tok.kind == "op" and tok.text in pairs:
                stack.append(tok)
            elif tok.kind == "op" and tok.text in ")]}":
                if pairs[stack[-1].text] != tok.text:
                    raise ParseError(tok.line, f"unbalanced brackets: '{tok.text}' closes "
                                                f"'{stack[-1].text}' of line {stack[-1].line}")
                stack.pop()

    # -- values
    def expression(self) -> Any:
        """expr := term {binop term}; a lone literal or aggregate stays structured."""
        start = self.i
        node = self.term()
        while self.peek().text.upper() in BINOPS and self.peek().kind in ("op", "id"):
            self.next()
            self.term()
            node = None
        if node is None:
            return Expr(" ".join(t.text for t in self.toks[start:self.i]), self.toks[start].line)
        return node

    def term(self) -> Any:
        tok = self.peek()
        if tok.kind == "op" and tok.text in "+-" or tok.up == "NOT":
            self.next()
            inner = self.term()
            if isinstance(inner, Lit) and inner.kind == "num" and tok.text in "+-":
                value = -inner.value if tok.text == "-" else inner.value
                return Lit(value, "num", tok.line, tok.text + inner.text)
            return Expr(tok.text + " " + getattr(inner, "text", "..."), tok.line)
        return self.primary()

    def primary(self) -> Any:
        tok = self.next()
        if tok.kind == "num":
            return Lit(tok.value, "num", tok.line, tok.text)
        if tok.kind == "str":
            return Lit(tok.value, "string", tok.line, '"' + tok.text + '"')
        if tok.up in ("TRUE", "FALSE"):
            return Lit(tok.up == "TRUE", "bool", tok.line, tok.up)
        if tok.kind == "op" and tok.text == "[":
            return self.aggregate(tok)
        if tok.kind == "op" and tok.text == "(":
            inner = self.expression()
            self.expect_op(")", f"to close '(' of line {tok.line}")
            return Expr(f"({getattr(inner, 'text', '...')})", tok.line)
        if tok.kind == "id" and tok.up not in RAPID_RESERVED:
            return self.reference(tok)
        raise ParseError(tok.line, f"expected a value, got '{tok.text}'")

    def reference(self, tok: Tok) -> Expr:
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
        return Expr("".join(t.text for t in self.toks[start:self.i]), tok.line)

    def aggregate(self, open_tok: Tok) -> Agg:
        items = []
        if self.is_op("]"):
            raise ParseError(open_tok.line, "empty aggregate '[]'")
        while True:
            items.append(self.expression())
            tok = self.peek()
            if tok.kind == "op" and tok.text == ",":
                self.next()
            elif tok.kind == "op" and tok.text == "]":
                self.next()
                return Agg(items, open_tok.line)
            else:
                raise ParseError(tok.line, f"unbalanced brackets: expected ',' or ']' in the aggregate "
                                            f"opened at line {open_tok.line}, got '{tok.text}'")

    # -- structure of initial values
    def check_value(self, decl: Decl) -> None:
        if decl.value is None:
            return
        if decl.dims:
            self.check_array(decl.value, decl.dims, decl.type_name, decl.name)
        else:
            self.check_type(decl.value, decl.type_name, decl.name)

    def check_array(self, node: Any, dims: tuple, type_name: str, where: str) -> None:
        if isinstance(node, Expr):
            return
        if not isinstance(node, Agg):
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
        if spec is None or isinstance(node, Expr):
            return
        if isinstance(spec, str):
            if isinstance(node, Agg):
                self.err(node.line, f"{where}: {type_name} takes one value, got an aggregate of "
                                    f"{len(node.items)} elements")
            elif node.kind != spec:
                self.err(node.line, f"{where}: expected a {spec} value, got {node.text}")
            return
        if not isinstance(node, Agg):
            self.err(node.line, f"{where}: {type_name} needs an aggregate of {len(spec)} components, "
                                f"got {node.text}")
            return
        if len(node.items) != len(spec):
            self.err(node.line, f"{where}: {type_name} needs {len(spec)} components, got {len(node.items)}")
            return
        for (component, sub), item in zip(spec, node.items):
            self.check_type(item, sub, f"{where}.{component}")
