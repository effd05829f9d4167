"""Spreadsheet-safe CSV text cells: the one writer and reader rule for every CSV the controller writes.

A spreadsheet opening a CSV runs a cell starting with ``=``, ``+``, ``-`` or ``@`` (and, in some tools, a tab or
carriage return) as a formula (``=cmd|' /C calc'!A0``). Text cells (ids, names, reasons) that start so are written
with a leading apostrophe, which spreadsheet tools show as text and do not evaluate (the OWASP rule). Numbers are
never touched: numeric columns are not passed through here, and a text cell that is a plain number (``-5``,
``+1.5e3``) is not a formula and is written as it is.

The rule round-trips: :func:`restore` undoes :func:`neutralise` exactly (a cell that already starts with
apostrophes before a formula character gets one more), so ids read back from our own files are the ids written.
"""
from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence

FORMULA_START = frozenset("=+-@\t\r")
_PLAIN_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def _formula_like(text: str) -> bool:
    core = text.lstrip("'")
    return core[:1] in FORMULA_START and not _PLAIN_NUMBER.fullmatch(core)


def neutralise(text: str) -> str:
    """``text`` as a CSV text cell a spreadsheet will not evaluate (``'`` prefixed when formula-like)."""
    return "'" + text if _formula_like(text) else text


def restore(text: str) -> str:
    """The text :func:`neutralise` was given (one ``'`` removed from a neutralised cell)."""
    return text[1:] if text[:1] == "'" and _formula_like(text) else text


def render_rows(header: Sequence[str], rows: Iterable[Sequence], text_columns: Iterable[int]) -> str:
    """CSV text (``\\n`` line ends) of ``header`` and ``rows``; the cells of ``text_columns`` (indices) are
    neutralised, every other cell is written as given (``str``)."""
    text = frozenset(text_columns)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow([neutralise(str(v)) if i in text else v for i, v in enumerate(row)])
    return buf.getvalue()
