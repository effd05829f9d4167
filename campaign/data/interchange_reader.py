"""Reading the interchange CSV (:mod:`campaign.data.interchange_csv`, where the format is described): the header
layout, the data cells, strict vectorised numbers, ids, sets and the nest and scalar columns, each with one-line
``DataError``s naming the file, line and column. ``read_csv`` strings these steps together; the column vocabulary
here is shared with :mod:`campaign.data.interchange_writer`."""
from __future__ import annotations

import csv
import itertools
import math
import re
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from campaign.errors import DataError
from campaign.io.csv_cells import restore

from .dataset import ENV_COLUMNS, SCALAR_COLUMNS, SETS

_QC_RE = re.compile(r"qc([1-9][0-9]*)")
_ORDER_RE = re.compile(r"(approach|move|move_before)([1-9][0-9]*)")   # a subset's places in the full order
SMR_COLUMNS = {2: ("x2", "y2", "z2"), 3: ("x3", "y3", "z3")}
_Q_RE = re.compile(r"q([1-9][0-9]*)")
_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUM_RE = re.compile(_NUM)
_COLUMN_RE = re.compile(rf"(?>{_NUM}\n)*+")  # a whole column joined with "\n"
BAD_ID_CHARS = frozenset(',;"\r\n')
MAX_ID_CHARS = 256  # point_id / nest_id length bound (ids end up in file names, terminal lines and reports)


def _show(text: str, limit: int = 40) -> str:
    """``'text'`` quoted for a message, shortened if long."""
    return "'" + (text if len(text) <= limit else text[: limit - 3] + "...") + "'"


@dataclass
class Layout:
    """What the header says: separator, column names and their positions."""

    sep: str
    names: list[str]  # lower-cased, stripped
    shown: list[str]  # as written (stripped), for messages
    n_joints: int
    smr: tuple[int, ...]  # extra SMR indices present: (), (2,), (2, 3)
    scalars: tuple[str, ...]  # optional scalar columns present
    has_qc: bool = False  # commanded joints qc1..qcn present
    env: tuple[str, ...] = ()  # environment columns present
    line: int | None = None  # the header's line number
    has_order: bool = False  # approach1..n, move1..n, move_before1..n, order present (a subset of a campaign)

    def index(self, name: str) -> int:
        return self.names.index(name)


def is_skipped(line: str) -> bool:
    """Blank lines and ``#`` comment lines are ignored."""
    stripped = line.strip()
    return not stripped or stripped.startswith("#")


def _split(line: str, sep: str) -> list[str]:
    """Fields of one line, stripped; csv-module parsing only if quoted."""
    if '"' in line:
        parts = next(csv.reader([line], delimiter=sep, skipinitialspace=True))
    else:
        parts = line.split(sep)
    return [p.strip() for p in parts]


def parse_header(line: str, src: str, line_no: int | None = None) -> Layout:
    """Validate the header line and return the column layout."""
    sep = ";" if line.count(";") > line.count(",") else ","
    shown = _split(line, sep)
    names = [s.lower() for s in shown]
    seen: set[str] = set()
    for pos, name in enumerate(names, start=1):
        if not name:
            raise DataError(src, f"header: empty column name at position {pos}")
        if name in seen:
            raise DataError(src, f"header: duplicate column {_show(shown[pos - 1])}")
        seen.add(name)
    n_joints = _check_known_columns(names, shown, src)
    smr = _check_smr_groups(seen, src, line_no)
    scalars = tuple(s for s in SCALAR_COLUMNS if s in seen)
    has_qc = _check_qc_columns(names, shown, n_joints, src, line_no)
    env = tuple(e for e in ENV_COLUMNS if e in seen)
    has_order = _check_order_columns(names, n_joints, src, line_no)
    return Layout(sep, names, shown, n_joints, smr, scalars, has_qc, env, line_no, has_order)


def order_columns(n_joints: int) -> list[str]:
    """The order-context columns of a subset, in write order."""
    return [f"{g}{k}" for g in ("approach", "move", "move_before") for k in range(1, n_joints + 1)] + ["order"]


def _check_order_columns(names: list[str], n_joints: int, src: str, line_no: int | None) -> bool:
    """The order-context columns come complete (all of ``order_columns``) or not at all; True if present."""
    wanted = order_columns(n_joints)
    have = [c for c in wanted if c in names]
    extra = [c for c in names if (m := _ORDER_RE.fullmatch(c)) and int(m.group(2)) > n_joints]
    if extra:
        raise DataError(src, f"header: '{extra[0]}' but {n_joints} joint columns q1..q{n_joints}", line=line_no,
                        column=f"'{extra[0]}'")
    if have and len(have) < len(wanted):
        missing = next(c for c in wanted if c not in names)
        raise DataError(src, f"header: missing column '{missing}' (the order columns approach1.., move1.., "
                        f"move_before1.., order come together)", line=line_no, column=f"'{missing}'")
    return bool(have)


def _check_qc_columns(names: list[str], shown: list[str], n_joints: int, src: str, line_no: int | None) -> bool:
    """Commanded joints ``qc1..qcn`` come complete, one per ``q`` column; True if present."""
    qc = {int(m.group(1)): as_written for name, as_written in zip(names, shown) if (m := _QC_RE.fullmatch(name))}
    if not qc:
        return False
    for k in sorted(qc):
        if k > n_joints:
            raise DataError(src, f"header: {len(qc)} commanded-joint columns but {n_joints} joint columns "
                            f"q1..q{n_joints} ('{qc[k]}' has no 'q{k}')", line=line_no, column=f"'{qc[k]}'")
    for k in range(1, n_joints + 1):
        if k not in qc:
            raise DataError(src, f"header: missing column 'qc{k}' ({len(qc)} commanded-joint columns but "
                            f"{n_joints} joint columns q1..q{n_joints})", line=line_no, column=f"'qc{k}'")
    return True


def _check_known_columns(names: list[str], shown: list[str], src: str) -> int:
    """Reject unknown columns, require the mandatory ones; return n joints."""
    known = {"point_id", "set", "x", "y", "z", *SCALAR_COLUMNS, *SMR_COLUMNS[2], *SMR_COLUMNS[3], "nest_id", *ENV_COLUMNS}
    joints = set()
    for name, as_written in zip(names, shown):
        match = _Q_RE.fullmatch(name)
        if match:
            joints.add(int(match.group(1)))
        elif name not in known and not _QC_RE.fullmatch(name) and not _ORDER_RE.fullmatch(name) and name != "order":
            raise DataError(src, f"header: unknown column {_show(as_written)}")
    n_joints = max(joints, default=1)
    for name in ("point_id", "set", *(f"q{k}" for k in range(1, n_joints + 1)), "x", "y", "z"):
        if name not in names:
            raise DataError(src, f"header: missing column '{name}'")
    return n_joints


def _check_smr_groups(present: set[str], src: str, line_no: int | None = None) -> tuple[int, ...]:
    """Second/third SMR columns come as complete groups, the third only with the second."""
    groups = []
    for k, cols in SMR_COLUMNS.items():
        have = [c for c in cols if c in present]
        if have and len(have) < 3:
            missing = next(c for c in cols if c not in present)
            raise DataError(src, f"header: missing column '{missing}' (needed with '{have[0]}')",
                            line=line_no, column=f"'{missing}'")
        if have:
            groups.append(k)
    if groups == [3]:
        raise DataError(src, "header: missing column 'x2' (x3,y3,z3 need x2,y2,z2)", line=line_no, column="'x2'")
    return tuple(groups)


class _Table:
    """Data cells of a block of CSV rows as one flat row-major list (``width`` cells per row)."""

    def __init__(self, flat: list[str], width: int, line_nos: list[int]) -> None:
        self.flat, self.width, self.line_nos = flat, width, line_nos

    def column(self, pos: int) -> list[str]:
        """Cells of column ``pos`` (0-based), one per row."""
        return self.flat[pos :: self.width]


def data_table(data: list[str], line_nos: list[int], layout: Layout, src: str) -> _Table:
    """Split data lines (on physical lines ``line_nos``) into cells (bulk, then checked)."""
    width, sep = len(layout.names), layout.sep
    _check_field_counts(data, line_nos, width, sep, src)
    block = sep.join(data)
    if '"' in block:  # quoted fields: let the csv module split each line
        return _Table([cell for line in data for cell in _split(line, sep)], width, line_nos)
    flat = block.split(sep)
    if " " in block or "\t" in block:
        flat = [cell.strip() for cell in flat]
    return _Table(flat, width, line_nos)


def _check_field_counts(data: list[str], line_nos: list[int], width: int, sep: str, src: str) -> None:
    """DataError at the first line whose number of fields is not ``width``."""
    for line, line_no in zip(data, line_nos):
        n_fields = len(_split(line, sep)) if '"' in line else line.count(sep) + 1
        if n_fields != width:
            raise DataError(src, f"expected {width} fields, got {n_fields}", line=line_no)


def _number_error(raw: str, name: str, line: int, src: str) -> DataError:
    """The DataError for a cell that is not a finite plain number."""
    try:
        value = float(raw.replace(",", "."))
    except ValueError:
        value = None
    if value is not None and not math.isfinite(value):
        what = f"expected a finite number, got {_show(raw)}"
    else:
        what = f"expected a number, got {_show(raw)}"
    return DataError(src, what, line=line, column=f"'{name}'")


def _first_bad_cell(table: _Table, positions: Sequence[int], decimal_comma: bool) -> tuple[int, int]:
    """(row, column position) of the first malformed number, in reading order."""
    for row in range(len(table.line_nos)):
        for pos in positions:
            cell = table.flat[row * table.width + pos]
            if not _NUM_RE.fullmatch(cell.replace(",", ".") if decimal_comma else cell):
                return row, pos
    raise AssertionError("no malformed cell found")  # pragma: no cover


def numeric_columns(table: _Table, layout: Layout, names: Sequence[str], src: str) -> np.ndarray:
    """(N, len(names)) float64 from the named columns; strict, vectorised: DataError at the first cell (in reading
    order) that is not a plain decimal number. Values out of range are inf here (``check_range``)."""
    positions = [layout.index(n) for n in names]
    cells = [cell for pos in positions for cell in table.column(pos)]  # column-major
    joined = "\n".join(cells) + "\n"
    decimal_comma = layout.sep == ";"
    if decimal_comma and "," in joined:
        joined = joined.replace(",", ".")
        cells = joined[:-1].split("\n")
    if not _COLUMN_RE.fullmatch(joined):
        row, pos = _first_bad_cell(table, positions, decimal_comma)
        raise _number_error(table.column(pos)[row], layout.shown[pos], table.line_nos[row], src)
    return np.array(cells, dtype=np.float64).reshape(len(positions), -1).T


def check_range(values: np.ndarray, table: _Table, layout: Layout, names: Sequence[str], src: str) -> None:
    """DataError at the first value of ``numeric_columns`` (row by row) that overflowed to inf."""
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        row, k = (int(v) for v in bad[0])
        pos = layout.index(names[k])
        raise DataError(src, f"number out of range: {_show(table.column(pos)[row])}", line=table.line_nos[row],
                        column=f"'{layout.shown[pos]}'")


def check_ids(
    ids: Sequence[str], sets: Sequence[str], fail: Callable[[int, str], DataError], ref: Callable[[int], str]
) -> None:
    """Unique non-empty point ids of at most ``MAX_ID_CHARS``; ``check`` rows may repeat an id among themselves
    (and ``nest`` rows). ``fail(i, what)`` builds the error for row i; ``ref(k)`` names row k. Vectorised: the first
    occurrence of every id from a sort of the ids' hashes (equal hashes compared as text)."""
    n = len(ids)
    length = np.fromiter(map(len, ids), np.int64, n)
    first = _first_occurrence(ids)
    codes = np.fromiter(map(_SET_CODES.get, sets, itertools.repeat(-1)), np.int8, n)
    repeat_ok = np.isin(codes, (SETS.index("check"), SETS.index("nest"))) & (codes[first] == codes)
    bad = np.flatnonzero((length == 0) | (length > MAX_ID_CHARS) | ((first != np.arange(n)) & ~repeat_ok))
    if not bad.size:
        return
    i = int(bad[0])
    pid = ids[i]
    if not pid:
        raise fail(i, "point_id is empty")
    if len(pid) > MAX_ID_CHARS:
        raise fail(i, f"point_id {pid[:40]!r}... is {len(pid)} characters long (at most {MAX_ID_CHARS})")
    raise fail(i, f"duplicate point_id {_show(pid)} (first {ref(int(first[i]))})")


def _first_occurrence(ids: Sequence[str]) -> np.ndarray:
    """(N,) index of the first row holding each row's id."""
    n = len(ids)
    h = np.fromiter(map(hash, ids), np.int64, n)
    order = np.argsort(h, kind="stable")
    hs = h[order]
    start = np.flatnonzero(np.concatenate([[True], hs[1:] != hs[:-1]]))      # runs of equal hashes
    first = np.empty(n, np.intp)
    first[order] = order[np.repeat(start, np.diff(np.append(start, n)))]
    for run in np.flatnonzero(np.diff(np.append(start, n)) > 1):            # equal hashes: compare the texts
        rows = order[start[run]:(start[run + 1] if run + 1 < len(start) else n)]
        seen: dict[str, int] = {}
        for r in rows:                                                      # rows in reading order (stable sort)
            first[r] = seen.setdefault(ids[r], r)
    return first


def check_scalars(extra: dict, layout: Layout, line_nos: list[int], src: str) -> None:
    """What the config would refuse or the physics cannot be: a negative ``payload_kg``; a negative ``t_s``, or
    one that goes back in time (rows are in measurement order)."""
    def where(name: str, i: int) -> dict:
        return {"line": int(line_nos[i]), "column": f"'{layout.shown[layout.index(name)]}'"}

    payload = extra.get("payload_kg")
    if payload is not None and (bad := np.flatnonzero(payload < 0)).size:   # NaN (nest rows) compares False
        raise DataError(src, f"payload_kg {payload[bad[0]]:g} is negative (a payload is a mass >= 0 kg)",
                        **where("payload_kg", bad[0]))
    t = extra.get("t_s")
    if t is None:
        return
    if (bad := np.flatnonzero(t < 0)).size:
        raise DataError(src, f"t_s {t[bad[0]]:g} is negative (seconds since the start of the measurement)",
                        **where("t_s", bad[0]))
    if (back := np.flatnonzero(np.diff(t) < 0)).size:
        i = back[0] + 1
        raise DataError(src, f"t_s goes back in time ({t[i]:g} s after {t[i - 1]:g} s on line {line_nos[i - 1]}): "
                             "rows must be in measurement order", **where("t_s", i))


def check_order_columns(approach: np.ndarray, order: np.ndarray, layout: Layout, line_nos: list[int],
                        src: str) -> None:
    """An approach is -1, 0 or +1; ``order`` is >= 0 and never decreases (rows are in measurement order)."""
    if (bad := np.argwhere(~np.isin(approach, (-1.0, 0.0, 1.0)))).size:
        i, j = bad[0]
        raise DataError(src, f"approach{j + 1} {approach[i, j]:g}: an approach is -1, 0 or +1", line=int(line_nos[i]),
                        column=f"'{layout.shown[layout.index(f'approach{j + 1}')]}'")
    column = f"'{layout.shown[layout.index('order')]}'"
    if (bad := np.flatnonzero(order < 0)).size:
        raise DataError(src, f"order {order[bad[0]]:g} is negative", line=int(line_nos[bad[0]]), column=column)
    if (back := np.flatnonzero(np.diff(order) < 0)).size:
        i = back[0] + 1
        raise DataError(src, f"order goes back ({order[i]:g} after {order[i - 1]:g}): rows must be in measurement "
                             "order", line=int(line_nos[i]), column=column)


def read_nest_ids(table: _Table, layout: Layout, sets: list[str], src: str) -> tuple[str, ...] | None:
    """The ``nest_id`` column: required (non-empty) on nest rows, empty elsewhere; nest rows need ``t_s``."""
    first = next((i for i, s in enumerate(sets) if s == "nest"), None)
    if "nest_id" not in layout.names:
        if first is not None:
            raise DataError(src, "a nest row needs a nest id, but there is no 'nest_id' column",
                            line=table.line_nos[first], column="'nest_id'")
        return None
    if first is not None and "t_s" not in layout.names:
        raise DataError(src, "nest rows need a 't_s' column (drift is a function of time)",
                        line=table.line_nos[first], column="'t_s'")
    col = [restore(v) for v in table.column(layout.index("nest_id"))]
    for i, (nid, s) in enumerate(zip(col, sets)):
        if len(nid) > MAX_ID_CHARS:
            raise DataError(src, f"nest_id {nid[:40]!r}... is {len(nid)} characters long (at most {MAX_ID_CHARS})",
                            line=table.line_nos[i], column=f"'{layout.shown[layout.index('nest_id')]}'")
        if (s == "nest") != bool(nid):
            what = ("nest row without a nest id" if s == "nest"
                    else f"nest_id {_show(nid)} on a {s} row (only nest rows have one)")
            raise DataError(src, what, line=table.line_nos[i], column=f"'{layout.shown[layout.index('nest_id')]}'")
    return tuple(col)


def blank_cells(table: _Table, layout: Layout, sets: list[str]) -> dict[str, np.ndarray]:
    """Empty cells that are allowed (joints, extra SMRs, temp_c, payload_kg on nest rows; environment and move
    columns anywhere): set to "0" in ``table`` for the strict parser; returns {column: row indices} to become NaN."""
    nest_rows = [i for i, s in enumerate(sets) if s == "nest"]
    nullable_on_nest = [f"q{k}" for k in range(1, layout.n_joints + 1)]
    nullable_on_nest += [f"qc{k}" for k in range(1, layout.n_joints + 1)] * layout.has_qc
    nullable_on_nest += [c for k in layout.smr for c in SMR_COLUMNS[k]]
    nullable_on_nest += [s for s in ("temp_c", "payload_kg") if s in layout.scalars]
    out: dict[str, np.ndarray] = {}
    anywhere = list(layout.env) + [c for c in order_columns(layout.n_joints) if c.startswith("move")] * layout.has_order
    for name, rows in [(c, nest_rows) for c in nullable_on_nest] + [(e, None) for e in anywhere]:
        pos = layout.index(name)
        col = table.column(pos)
        empty = [i for i in (range(len(col)) if rows is None else rows) if col[i] == ""]
        for i in empty:
            table.flat[i * table.width + pos] = "0"
        if empty:
            out[name] = np.array(empty, dtype=np.intp)
    return out


_SET_NAMES = {name: name for name in SETS}      # one string object per set name (no copy per row)
_SET_CODES = {name: k for k, name in enumerate(SETS)}


def parse_sets(raw: list[str], line_nos: list[int], src: str) -> list[str]:
    """Lower-cased set names; DataError for anything but calib/test/check/nest."""
    sets = [_SET_NAMES.get(s.lower()) for s in raw]
    if None not in sets:
        return sets
    for i, s in enumerate(sets):
        if s is None:
            raise DataError(
                src, f"expected calib, test, check or nest, got {_show(raw[i])}", line=line_nos[i], column="'set'"
            )
    return sets
