"""The emulator's RAPID model reads through the strict lexer and parser (one reader for RAPID)."""
from __future__ import annotations

import pytest

from drivers.rapid import check_rapid_syntax
from drivers.rapid.values import RapidSyntaxError, parse_literal, parse_module, render

pytestmark = pytest.mark.unit

GOOD = '''MODULE Cell
  PERS num n := 3;
  VAR robtarget p;
  PERS string s := "say ""hi""";
  PROC main()
    helper;
    Stop;
  ENDPROC
  PROC helper()
    n := n + 1;
  ENDPROC
  PROC withargs(num x)
  ENDPROC
ENDMODULE
'''


def test_literals_are_floats_strings_bools_and_lists():
    assert parse_literal("[1, -2.5, 9E+09, TRUE, \"a\"\"b\"]") == [1.0, -2.5, 9e9, True, 'a"b']
    assert isinstance(parse_literal("3"), float)
    assert render(parse_literal("[[1,2],[3,4]]")) == "[[1,2],[3,4]]"


@pytest.mark.parametrize("text", ["", "[1,2", "[1,,2]", "1 2", "abc", "[1, x + 1]", "[]"])
def test_non_literals_are_refused(text):
    with pytest.raises(RapidSyntaxError):
        parse_literal(text)


def test_module_outline_from_the_strict_parser():
    m = parse_module(GOOD)
    assert m.name == "Cell" and m.has_main
    assert m.routines == {"main": "", "helper": "", "withargs": "num x"}
    assert m.main_calls == frozenset({"helper"})                   # Stop is an instruction, not a procedure
    assert m.symbols["n"].value == "3" and m.symbols["s"].value == '"say ""hi"""'
    assert m.symbols["p"].value == "[[0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,0,0,0]]"


@pytest.mark.parametrize("bad", [
    GOOD.replace("n := n + 1;", "n := n + 1"),                     # missing ';' (the old regex reader let it pass)
    GOOD.replace("PERS num n := 3;", "PERS num n := [1,2];"),      # value does not fit the type
    GOOD.replace("ENDPROC\n  PROC helper", "PROC helper"),         # unbalanced PROC
    GOOD.replace("PERS num n", "PERS nosuchtype n"),
])
def test_emulator_refuses_what_the_checker_refuses(bad):
    assert check_rapid_syntax(bad)
    with pytest.raises(RapidSyntaxError):
        parse_module(bad)
