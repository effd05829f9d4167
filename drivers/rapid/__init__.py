"""RAPID (ABB) in one place: literals and layout (``literals``), the module checker and reader (``parser`` on
``statements``, ``expressions`` and ``lexer``), RAPID values (``values``), and the packaged ``CalServer.mod``
(:func:`calserver_text`).

Used by the target writer (``campaign.correct.rapid_module``), the ABB driver (``drivers.abb_rws``) and the RWS
emulator.
"""

from __future__ import annotations

from importlib import resources

from .lexer import RapidExpr
from .parser import check_rapid_syntax, parse_rapid_module

__all__ = ["RapidExpr", "check_rapid_syntax", "parse_rapid_module", "calserver_text"]


def calserver_text() -> str:
    """Text of the packaged ``drivers/rapid/CalServer.mod`` (latin-1, as the controller stores it)."""
    return resources.files("drivers").joinpath("rapid/CalServer.mod").read_text(encoding="latin-1")
