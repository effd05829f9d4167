"""The interchange CSV: measured data in and out of the campaign controller.

Format (one row per measurement, rows in measurement order)::

    point_id,set,q1,q2,q3,q4,q5,q6,x,y,z[,x2,y2,z2[,x3,y3,z3]][,t_s][,temp_c][,payload_kg]

* ``point_id``: non-empty text of at most 256 characters, unique; only ``check`` rows may repeat an id
  (the same check pose measured again), and never an id of a calib/test row.
* ``set``: ``calib`` | ``test`` | ``check`` | ``nest`` (case-insensitive).
  ``nest`` rows are readings of a fixed reference nest (column ``nest_id``,
  required on them, empty elsewhere; ``t_s`` required); their joint columns
  may be empty (NaN) and their ``point_id`` may repeat among nest rows.
* ``q1..qn``: joint values in degrees as the controller reports them; any
  number n >= 1 of joints, contiguous from ``q1``.
* optional ``qc1..qcn``: the commanded joints (deg) when ``q1..qn`` are the
  read-back ones; exactly as many as ``q`` columns.
* ``x,y,z``: SMR centre in mm in the tracker frame; ``x2..z2`` / ``x3..z3``
  optional second and third SMR (all three columns of a group, and the
  third only with the second).
* optional ``t_s`` (s), ``temp_c`` (deg C), ``payload_kg`` (kg); when a
  column is present every row needs a value (leave the column out if unknown),
  except nest rows (may be empty). ``t_s`` is >= 0 and never decreases (rows
  are in measurement order); ``payload_kg`` is >= 0.  Optional ``env_temp_c`` (deg C),
  ``env_pressure_hpa`` (hPa), ``env_humidity_pct`` (%): the tracker's weather
  station; an empty cell means not read (NaN).
* Approach directions and last moves come from row order (:meth:`Dataset.approach_sign`). A subset of a campaign
  (``campaign select``) carries them from the full order instead, in optional columns that come together:
  ``approach1..n`` (-1/0/+1), ``move1..n`` and ``move_before1..n`` (deg, the signed last move and the one before;
  empty = unknown) and ``order`` (the row's position in the full measurement order).

Header names are matched case-insensitively and may come in any order;
unknown or repeated columns are errors.  Blank lines and lines starting with
``#`` are ignored, but for a ``# provenance: TEXT`` line before the header: where the rows came from
(``campaign import`` and ``campaign select`` write one; :attr:`Dataset.provenance`).
A UTF-8 BOM is tolerated.  The separator is ``,``, or ``;``
when the header uses ``;`` -- then a decimal comma (``1,5``) is accepted too.
Fields may be double-quoted but not span lines.  A text cell (``point_id``, ``nest_id``) that a spreadsheet would
run as a formula is written with a leading ``'`` and read back without it (:mod:`campaign.io.csv_cells`).
Numbers are plain decimal (``-12.5``, ``1e-3``); ``nan``/``inf``, ``1_000`` and hex are rejected.

Every input problem raises :class:`campaign.errors.DataError` with a single
line naming the file and the line/column, e.g.
``data.csv: line 7, column 'q3': expected a number, got 'abc'``.

:func:`write_csv` writes floats with ``repr`` (shortest text that round-trips
exactly), so ``read_csv(write_csv(d))`` gives bit-identical numbers.

:func:`read_csv` and :func:`write_csv` string together the steps of :mod:`campaign.data.interchange_reader` (header
layout, cells, numbers, ids) and :mod:`campaign.data.interchange_writer` (column order, writability).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from campaign.errors import DataError
from campaign.io.csv_cells import neutralise
from campaign.io.durable import atomic_write
from campaign.io.terminal_text import clean

from .dataset import SETS, Dataset, OrderContext  # noqa: F401  (SETS and Dataset are re-exported)
from .interchange_blocks import read_columns
from .interchange_reader import check_order_columns, check_scalars
from .interchange_writer import blank_allowed, check_writable, header_columns, numeric_block

__all__ = ["SETS", "Dataset", "read_csv", "write_csv"]


def read_csv(path: str | os.PathLike) -> Dataset:
    """Read and strictly validate an interchange CSV file (see module doc).

    Returns a :class:`Dataset` (``sigma_mm`` None; ``source`` = ``str(path)``).
    Raises :class:`DataError` (one line naming file and line/column) on any
    problem.  Read in blocks (:mod:`campaign.data.interchange_blocks`): the text of the file is never held whole;
    10^6 rows in about 10 s.
    """
    src = str(path)
    with open(path, "rb") as fh:
        cols = read_columns(fh, src)
    layout, names = cols.layout, cols.names
    values = np.concatenate(cols.values)
    cols.values.clear()
    line_nos = np.concatenate(cols.line_nos)
    n = layout.n_joints
    extra: dict[str, Any] = {}
    for j, k in enumerate(layout.smr):
        extra[f"p{k}_tracker_mm"] = values[:, n + 3 + 3 * j : n + 6 + 3 * j]
    for j, name in enumerate(layout.scalars):
        extra[name] = values[:, n + 3 + 3 * len(layout.smr) + j]
    check_scalars(extra, layout, line_nos, src)
    m = n + 3 + 3 * len(layout.smr) + len(layout.scalars)
    if layout.has_qc:
        extra["qc_deg"] = values[:, m : m + n]
    for j, name in enumerate(layout.env):
        extra[name] = values[:, m + n * layout.has_qc + j]
    if layout.has_order:
        o = values[:, m + n * layout.has_qc + len(layout.env):]
        check_order_columns(o[:, :n], o[:, 3 * n], layout, line_nos, src)
        extra["order_context"] = OrderContext(o[:, :n], np.radians(o[:, n:2 * n]), np.radians(o[:, 2 * n:3 * n]),
                                              o[:, 3 * n])
    nest_ids = None if cols.nest_ids is None else tuple(cols.nest_ids)
    return Dataset(tuple(cols.ids), tuple(cols.sets), values[:, :n], values[:, n : n + 3], source=src,
                   nest_id=nest_ids, provenance=_provenance(cols.comments), **extra)


PROVENANCE = "# provenance:"


def _provenance(comments: list[str]) -> str:
    """The text of the last ``# provenance:`` line before the header ("" without one)."""
    found = [ln.strip()[len(PROVENANCE):].strip() for ln in comments if ln.strip().startswith(PROVENANCE)]
    return found[-1] if found else ""


def write_csv(path: str | os.PathLike, dataset: Dataset) -> None:
    """Write ``dataset`` as an interchange CSV (comma separated, ``\\n`` ends).

    Only the columns present are written; ``sigma_mm`` is not part of the
    format and is dropped.  Floats use ``repr`` (shortest exact round trip),
    so reading the file back gives identical float64 values.  The file is
    written to a temporary name and renamed into place.
    """
    src = str(path)
    numbers = numeric_block(dataset)
    header = header_columns(dataset)
    check_writable(dataset, src, numbers, blank_allowed(dataset, header))
    lines = [",".join(header)]
    if dataset.provenance:                      # one line: control characters and line breaks escaped
        lines.insert(0, f"{PROVENANCE} " + clean(dataset.provenance).replace("\n", "\\n"))
    nest_ids = dataset.nest_id if dataset.nest_id is not None else None
    cell = (lambda v: "" if v != v else repr(v)) if np.isnan(numbers).any() else repr  # noqa: E731
    for i, (pid, set_name, row) in enumerate(zip(dataset.point_id, dataset.set, numbers.tolist())):
        tail = [neutralise(nest_ids[i])] if nest_ids is not None else []
        lines.append(",".join([neutralise(pid), set_name, *map(cell, row), *tail]))
    atomic_write(path, ("\n".join(lines) + "\n").encode("utf-8"))
