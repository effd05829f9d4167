"""Importers: measured campaigns in other layouts -> the interchange :class:`Dataset` (``campaign import``).

``target-dif``: the layout of the public UR5 + laser-tracker campaign vendored in ``tests/data/serial_robots_datasets``
(P. Jacobi, MIT licence). One CSV per set, columns::

    step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif,joint_1,...,joint_n

``step_order`` the measurement order (integers, unique per file), ``x_t..z_t`` the target position of the SMR
(mm, robot base frame after the source's tracker-to-base set-up), ``x_dif..z_dif`` the difference between
target and reached position (mm), ``joint_k`` the commanded joints (deg). The measured position is
``target + dif_sign * dif``; the source does not state the sign. :data:`DIF_SIGN` (+1: dif = reached - target) is
the sign that gives back the recorded tracker readings: ``target + dif`` has exactly six decimals (mm) in every
coordinate of the public files, ``target - dif`` in 0.3 % (chance). A gravity-compliance fit agrees (with +1 the
fitted deflection lowers the SMR, the more the farther it reaches); the nominal residual cannot tell the signs apart
(``bench/bench_ur5.py`` prints all three). ``dif_sign`` overrides it.

A format-specific importer rather than a column mapping: the measured position is computed (target + sign x dif),
the rows are re-ordered by ``step_order`` and each file is one set, none of which a renaming of columns expresses.

Rows come out in measurement order: the calibration file's rows sorted by ``step_order``, then the test file's
(the source gives no order between the files); point ids carry the step: ``G000`` .. (calib), ``R00`` .. (test).
Every problem is one :class:`DataError` line naming the file, the line and the column.
"""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from .dataset import Dataset
from campaign.errors import DataError

DIF_SIGN = 1.0                # measured = target + dif (dif = reached - target), see the module doc
MAX_STEP = 1e9
_TARGET = ("x_t", "y_t", "z_t")
_DIF = ("x_dif", "y_dif", "z_dif")


def _read_rows(path: str | os.PathLike) -> list[tuple[int, list[str]]]:
    """[(line number, fields)] of a comma-separated file, the header first; blank and ``#`` lines skipped."""
    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(src, "not valid UTF-8 text") from None
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise DataError(src, "empty file (no header)")
    try:
        cells = list(csv.reader([ln for _, ln in lines]))
    except csv.Error as exc:
        raise DataError(src, f"not a CSV file: {exc}") from None
    return [(n, [c.strip() for c in fields]) for (n, _), fields in zip(lines, cells)]


def _columns(header: list[str], src: str, line: int) -> tuple[int, list[str]]:
    """(number of joints, column names in read order); DataError naming a missing or unknown column."""
    n = sum(h.startswith("joint_") for h in header)
    want = ["step_order", *_TARGET, *_DIF] + [f"joint_{k}" for k in range(1, n + 1)]
    missing = [c for c in want if c not in header]
    if missing or n == 0:
        raise DataError(src, f"not a step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif,joint_1..joint_n file: missing column "
                             f"{(missing or ['joint_1'])[0]!r}", line=line)
    extra = [h for h in header if h not in want]
    if extra or len(set(header)) != len(header):
        raise DataError(src, f"unexpected or repeated column {(extra or header)[0]!r}", line=line)
    return n, want


def _number(cell: str, src: str, line: int, column: str) -> float:
    try:
        value = float(cell)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise DataError(src, f"expected a finite number, got {cell[:40]!r}", line=line, column=f"'{column}'")
    return value


def read_target_dif_file(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(step_order (N,) int, target (N, 3) mm, dif (N, 3) mm, joints (N, n) deg) of one file, rows sorted by
    ``step_order``."""
    src = str(path)
    (header_line, header), *rows = _read_rows(path)
    header = [h.lower() for h in header]
    n, names = _columns(header, src, header_line)
    if not rows:
        raise DataError(src, "no data rows")
    pos = [header.index(c) for c in names]
    values = np.empty((len(rows), len(names)))
    for r, (line, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise DataError(src, f"expected {len(header)} fields, got {len(fields)}", line=line)
        values[r] = [_number(fields[p], src, line, c) for p, c in zip(pos, names)]
    step = values[:, 0]
    bad = np.flatnonzero((step != np.round(step)) | (step < 0) | (step > MAX_STEP))
    if len(bad):
        raise DataError(src, f"step_order must be an integer in [0, {MAX_STEP:g}], got {step[bad[0]]:g}",
                        line=rows[bad[0]][0], column="'step_order'")
    order = np.argsort(step, kind="stable")
    dup = np.flatnonzero(np.diff(step[order]) == 0)
    if len(dup):
        raise DataError(src, f"step_order {int(step[order[dup[0]]])} appears twice",
                        line=rows[order[dup[0] + 1]][0], column="'step_order'")
    v = values[order]
    return v[:, 0].astype(int), v[:, 1:4], v[:, 4:7], v[:, 7:7 + n]


def import_target_dif(calib_csv: str | os.PathLike, test_csv: str | os.PathLike | None = None,
                      dif_sign: float = DIF_SIGN) -> Dataset:
    """The campaign of ``calib_csv`` (set calib) and ``test_csv`` (set test, optional) as one interchange
    :class:`Dataset`: joints = the commanded ``joint_k`` (deg), xyz = ``target + dif_sign * dif`` (mm, in the
    source's base frame, which the calibration registers like any tracker frame), rows in measurement order."""
    if dif_sign not in (1.0, -1.0):
        raise ValueError(f"dif_sign must be +1 or -1, got {dif_sign}")
    parts = [("calib", "G", calib_csv)] + ([("test", "R", test_csv)] if test_csv is not None else [])
    ids, sets, qs, ps = [], [], [], []
    for set_name, prefix, path in parts:
        step, target, dif, q = read_target_dif_file(path)
        if qs and q.shape[1] != qs[0].shape[1]:
            raise DataError(str(path), f"{q.shape[1]} joint columns, the calibration file has {qs[0].shape[1]}")
        width = max(2, len(str(int(step.max()))))
        ids += [f"{prefix}{s:0{width}d}" for s in step]
        sets += [set_name] * len(step)
        qs.append(q)
        ps.append(target + dif_sign * dif)
    source = str(calib_csv) if test_csv is None else f"{calib_csv} + {test_csv}"
    files = str(calib_csv) if test_csv is None else f"{calib_csv} (calib) and {test_csv} (test)"
    return Dataset(tuple(ids), tuple(sets), np.vstack(qs), np.vstack(ps), source=source,
                   provenance=f"imported from {files} (campaign import target-dif)")
