"""RAPID (ABB) in one place: literals and layout (``literals``), the module checker and reader (``parser`` on
``statements``, ``expressions`` and ``lexer``), RAPID values (``values``), and the packaged ``CalServer.mod``
(:func:`calserver_text`).

Used by the target writer (``campaign.correct.rapid_module``), the ABB driver (``drivers.abb_rws``) and the RWS
emulator.
"""

from __future__ import annotations

from importlib import resources

from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "lexer": ("RapidExpr",),
    "literals": ("RAPID_MAX_LINE_ID", "RAPID_UNUSED", "fixed_literal", "fmt_jointtarget", "fmt_num", "fmt_robtarget",
                 "fmt_string", "parse_num", "parse_string", "rapid_aggregate", "rapid_array_lines",
                 "rapid_ident_problem", "rapid_string"),
    "parser": ("check_rapid_syntax", "parse_rapid_module"),
    "values": ("Module", "RapidSyntaxError", "SHAPES", "Symbol", "matches", "parse_literal", "parse_module",
               "render"),
}
__all__ = ["calserver_text", *(name for names in _HOMES.values() for name in names)]
__getattr__ = lazy_exports(__name__, _HOMES)


def calserver_text() -> str:
    """Text of the packaged ``drivers/rapid/CalServer.mod`` (latin-1, as the controller stores it)."""
    return resources.files("drivers").joinpath("rapid/CalServer.mod").read_text(encoding="latin-1")
