"""Reading an interchange CSV in blocks of lines (:mod:`campaign.data.interchange_csv`): memory bounded by the
dataset itself at any size, never by the file's text, and the same one-line error a whole-file read gives.

The file is read, decoded and parsed ``READ_BYTES`` at a time by the steps of
:mod:`campaign.data.interchange_reader`. The checks come in a fixed order of kinds (``KINDS``: encoding, header,
field counts, sets, nest ids, point ids, number syntax, number range), and an input with several problems reports
the first problem of the earliest kind, wherever it is in the file: what reading the whole file and then checking
it kind by kind would report. Once a problem is found, later blocks are only checked for problems of earlier kinds.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import BinaryIO, Iterator

import numpy as np

from campaign.errors import DataError
from campaign.io.csv_cells import restore

from .interchange_reader import (SMR_COLUMNS, Layout, blank_cells, check_ids, check_range, data_table, is_skipped,
                                 numeric_columns, order_columns, parse_header, parse_sets, read_nest_ids)

READ_BYTES = 1 << 22        # text per block (about 20 000 rows of a 6-joint campaign)
KINDS = ("encoding", "header", "fields", "sets", "nest ids", "point ids", "number syntax", "number range")
_BOM = b"\xef\xbb\xbf"


def _kind(name: str) -> int:
    return KINDS.index(name)


def decoded_blocks(fh: BinaryIO, src: str) -> Iterator[tuple[int, list[str]]]:
    """(physical number of the first line, lines) of consecutive blocks of the file: BOM and ``\\r`` removed.
    Bad UTF-8 raises at once (the earliest kind of problem)."""
    line_no = 1
    while raw := fh.readlines(READ_BYTES):
        blob = b"".join(raw)
        bom = line_no == 1 and blob.startswith(_BOM)
        try:
            text = blob.decode("utf-8-sig" if line_no == 1 else "utf-8")
        except UnicodeDecodeError as exc:
            offset = exc.start + (3 if bom else 0)
            raise DataError(src, "not valid UTF-8 text", line=line_no + blob.count(b"\n", 0, offset)) from None
        lines = text.split("\n")
        if text.endswith("\n"):
            lines.pop()
        yield line_no, [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
        line_no += len(raw)


@dataclass
class Columns:
    """What the data rows of a file hold, gathered block by block: how many (``rows``), their ids, sets, nest ids,
    physical line numbers and the numeric columns ``names`` (``values``: one (rows, len(names)) array per block), the
    comment lines before the header (``comments``); the first problem found (``kind`` its index in ``KINDS``,
    ``len(KINDS)`` when none)."""
    layout: Layout | None = None
    rows: int = 0
    names: list[str] = field(default_factory=list)
    ids: list[str] = field(default_factory=list)
    sets: list[str] = field(default_factory=list)
    nest_ids: list[str] | None = None
    comments: list[str] = field(default_factory=list)     # the ``#`` lines before the header
    line_nos: list[np.ndarray] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)
    kind: int = len(KINDS)
    error: DataError | None = None

    def note(self, kind: str, error: DataError) -> None:
        """Keep ``error`` when it is of an earlier kind than the problem found so far (blocks come in order)."""
        if _kind(kind) < self.kind:
            self.kind, self.error = _kind(kind), error
            self.values.clear()                 # the file will not be read: keep what later checks need only

    def wants(self, kind: str) -> bool:
        return _kind(kind) < self.kind


def numeric_names(layout: Layout) -> list[str]:
    """The numeric columns of a layout in the order ``read_csv`` takes them apart: joints, SMRs, scalars, then
    commanded joints, environment and order context."""
    n = layout.n_joints
    names = [f"q{k}" for k in range(1, n + 1)] + ["x", "y", "z"]
    for k in layout.smr:
        names += SMR_COLUMNS[k]
    names += layout.scalars
    names += [f"qc{k}" for k in range(1, n + 1)] * layout.has_qc + list(layout.env)
    return names + order_columns(n) * layout.has_order


def read_columns(fh: BinaryIO, src: str) -> Columns:
    """The data rows of an interchange CSV file, checked block by block (see the module docstring); raises the
    first problem of the earliest kind."""
    out = Columns()
    for line_no, lines in decoded_blocks(fh, src):
        start = 0
        if out.layout is None and out.wants("header"):
            start = next((i for i, ln in enumerate(lines) if not is_skipped(ln)), None)
            out.comments += [ln for ln in lines[:start] if ln.strip().startswith("#")]
            if start is None:
                continue
            try:
                out.layout = parse_header(lines[start], src, line_no + start)
            except DataError as exc:
                out.note("header", exc)
                continue
            out.names = numeric_names(out.layout)
            out.nest_ids = [] if "nest_id" in out.layout.names else None
            start += 1
        if out.layout is not None and out.wants("fields"):
            _block(out, lines, line_no, start, src)
    if out.layout is None and out.wants("header"):
        out.note("header", DataError(src, "no data rows (empty file, no header)"))
    elif not out.rows and out.wants("fields"):
        out.note("fields", DataError(src, "no data rows"))
    if out.wants("point ids"):
        try:
            line_nos = np.concatenate(out.line_nos)
            check_ids(out.ids, out.sets, lambda i, what: DataError(src, what, line=int(line_nos[i])),
                       lambda k: f"on line {int(line_nos[k])}")
        except DataError as exc:
            out.note("point ids", exc)
    if out.error is not None:
        raise out.error
    return out


def _block(out: Columns, lines: list[str], line_no: int, start: int, src: str) -> None:
    """Check and parse the data lines of one block (``lines[start:]``, the first on physical line ``line_no +
    start``) into ``out``; a problem is noted and ends the block."""
    layout = out.layout
    line_nos = [line_no + i for i in range(start, len(lines)) if not is_skipped(lines[i])]
    out.rows += len(line_nos)
    if not line_nos:
        return
    try:
        table = data_table([lines[n - line_no] for n in line_nos], line_nos, layout, src)
    except DataError as exc:
        return out.note("fields", exc)
    if not out.wants("sets"):
        return
    try:
        sets = parse_sets(table.column(layout.index("set")), line_nos, src)
    except DataError as exc:
        return out.note("sets", exc)
    if not out.wants("nest ids"):
        return
    try:
        nest_ids = read_nest_ids(table, layout, sets, src)
    except DataError as exc:
        return out.note("nest ids", exc)
    if out.wants("point ids"):
        out.ids += [restore(v) for v in table.column(layout.index("point_id"))]
        out.sets += sets
        out.line_nos.append(np.array(line_nos, np.int64))
        if out.nest_ids is not None:
            out.nest_ids += nest_ids
    if not out.wants("number syntax"):
        return
    blanks = blank_cells(table, layout, sets)
    try:
        values = numeric_columns(table, layout, out.names, src)
    except DataError as exc:
        return out.note("number syntax", exc)
    if not out.wants("number range"):
        return
    try:
        check_range(values, table, layout, out.names, src)
    except DataError as exc:
        return out.note("number range", exc)
    for name, rows in blanks.items():
        values[rows, out.names.index(name)] = np.nan
    if out.error is None:
        out.values.append(values)
