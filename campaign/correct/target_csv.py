"""CSV of corrected and rejected targets (exact floats, round trip; text cells spreadsheet-safe, see
:mod:`campaign.io.csv_cells`)."""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path
from typing import Iterable, Sequence

from campaign.errors import one_line
from campaign.io.csv_cells import render_rows, restore
from campaign.io.durable import atomic_write
from .bounds import CorrectedTarget, Rejected, require_writable

def _csv_float(x: float) -> str:
    """Shortest exact text of a float ('nan' for nan)."""
    return repr(float(x))


def _csv_header(n: int, with_std: bool = True) -> list[str]:
    return (["target_id"] + [f"q{j}" for j in range(1, n + 1)] + [f"q{j}_nominal" for j in range(1, n + 1)]
            + ["x_cmd", "y_cmd", "z_cmd", "qw", "qx", "qy", "qz", "cf1", "cf4", "cf6", "cfx",
               "predicted_error_mm", "predicted_rot_err_deg", "solver_tolerance_mm"]
            + (["predicted_std_mm"] if with_std else []))


def render_targets_csv(targets: Iterable[CorrectedTarget], *, q_min_deg: Sequence[float],
                       q_max_deg: Sequence[float]) -> str:
    """Text of the targets CSV (see :func:`write_targets_csv`)."""
    items = require_writable(targets, q_min_deg, q_max_deg)
    with_std = any(not math.isnan(float(t.predicted_std_mm)) for t in items)   # no all-nan column
    rows = ([t.target_id, *map(_csv_float, t.q_corrected_deg), *map(_csv_float, t.q_nominal_deg),
             *map(_csv_float, t.p_command_base_mm), *map(_csv_float, t.quat_command_wxyz),
             *(str(int(c)) for c in t.confdata), _csv_float(t.predicted_error_mm),
             _csv_float(t.predicted_rot_err_deg), _csv_float(t.solver_tolerance_mm)]
            + ([_csv_float(t.predicted_std_mm)] if with_std else [])
            for t in items)
    return render_rows(_csv_header(len(q_min_deg), with_std), rows, text_columns=(0,))


def write_targets_csv(path: str | os.PathLike, targets: Iterable[CorrectedTarget], *,
                      q_min_deg: Sequence[float], q_max_deg: Sequence[float]) -> Path:
    """Write the accepted targets as CSV atomically; return the path.

    Columns ``target_id, q1..qn`` (corrected, deg), ``q1_nominal..qn_nominal``
    (deg), ``x_cmd, y_cmd, z_cmd`` (mm, base), ``qw, qx, qy, qz``, ``cf1, cf4,
    cf6, cfx``, ``predicted_error_mm`` (nan: unknown), ``predicted_rot_err_deg``
    (nan unless three SMRs measured orientation), ``solver_tolerance_mm``,
    ``predicted_std_mm`` (only when some target has one: GPR layer).  Floats are written exactly (``repr``), so
    :func:`read_corrected_targets_csv` gives back identical values.  ValueError, writing
    nothing, for an invalid target or one outside ``[q_min_deg, q_max_deg]``.
    """
    text = render_targets_csv(targets, q_min_deg=q_min_deg, q_max_deg=q_max_deg)
    return atomic_write(path, text.encode("utf-8"))


def read_corrected_targets_csv(path: str | os.PathLike) -> list[CorrectedTarget]:
    """Targets from a CSV written by :func:`write_targets_csv`; ValueError on a malformed file."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{path}: empty file")
    header = rows[0]
    n = sum(1 for h in header if re.fullmatch(r"q[0-9]+", h))
    with_std = header[-1:] == ["predicted_std_mm"]
    if n == 0 or header != _csv_header(n, with_std):
        raise ValueError(f"{path}: not a targets CSV header: {','.join(header)}")
    out = []
    for k, row in enumerate(rows[1:], 2):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {k}: {len(row)} fields, expected {len(header)}")
        try:
            nums = [float(v) for v in row[1:2 * n + 8]]
            conf = tuple(int(v) for v in row[2 * n + 8:2 * n + 12])
            err, rot, tol = (float(v) for v in row[2 * n + 12:2 * n + 15])
            std = float(row[2 * n + 15]) if with_std else math.nan
        except ValueError as e:
            raise ValueError(f"{path}: line {k}: {e}") from None
        out.append(CorrectedTarget(restore(row[0]), tuple(nums[n:2 * n]), tuple(nums[:n]), tuple(nums[2 * n:2 * n + 3]),
                                   tuple(nums[2 * n + 3:2 * n + 7]), conf, tol, err, rot, std))
    return out


def write_rejected_csv(path: str | os.PathLike, rejected: Iterable[Rejected]) -> Path:
    """Write ``target_id,reason`` rows of the rejected targets atomically; return the path."""
    text = render_rows(["target_id", "reason"], ([r.target_id, one_line(r.reason)] for r in rejected),
                       text_columns=(0, 1))
    return atomic_write(path, text.encode("utf-8"))
