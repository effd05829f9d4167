"""Per-point section of report.json: what the HTML report's figures are drawn from.

Every row with joint values (calib, test, check) gets its id, set, joints (deg), measured SMR position in the
robot base frame (mm, through the calibrated registration) and, per stage, the error measured - predicted
(mm, base-frame axes). Rows without joints (reference nests) get their position only. Compact: rounded to 0.1 um
and 1e-4 deg, which is far below any figure the report shows.

Up to ``POINTS_INLINE_MAX`` rows the table is inline in report.json (lists, null for missing). Beyond, report.json
holds a reference ``{"file": "points.csv", "format": "campaign-points/1", "n": N, "columns": [...]}`` and the
rows go to ``points.csv`` beside it: one row per point, columns ``set, used, t_s, q1..qn, x, y, z`` then
``<stage>_ex, <stage>_ey, <stage>_ez`` per stage, ``pred_std_mm`` with a GPR layer (test rows; the report's
``test_pred_std_mm.per_point_mm`` then points here), ``point_id`` last (CSV-quoted), ``nan`` for missing.
:meth:`PointTable.of` reads either form.
"""
from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from campaign.errors import DataError
from campaign.io.csv_cells import neutralise, restore
from campaign.io.durable import atomic_write

POINTS_INLINE_MAX = 10_000           # rows inline in report.json; more go to points.csv
POINTS_FILE = "points.csv"
POINTS_FORMAT = "campaign-points/1"
CSV_ROWS = 20_000                    # rows of points.csv formatted or parsed at a time


@dataclass(frozen=True, eq=False)
class PointTable:
    """Per-point rows (N): ``q_deg`` (N, n), ``p_base_mm`` (N, 3), ``err_base_mm`` {stage: (N, 3)} mm, ``used``
    (N,) 1 = in the fit, 0 = excluded calib row, NaN = not a calib row, ``t_s`` (N,) or None; NaN = missing."""
    point_id: tuple[str, ...]
    set: tuple[str, ...]
    q_deg: np.ndarray
    p_base_mm: np.ndarray
    err_base_mm: dict
    used: np.ndarray
    t_s: np.ndarray | None = None
    pred_std_mm: np.ndarray | None = None     # (N,) GPR predictive std of test rows (side file only)

    def __len__(self) -> int:
        return len(self.point_id)

    def to_json(self) -> dict:
        """The inline ``points`` dict of report.json (rounded lists, null for missing)."""
        return {"point_id": list(self.point_id), "set": list(self.set), "q_deg": _rounded(self.q_deg, 4),
                "p_base_mm": _rounded(self.p_base_mm, 4),
                "err_base_mm": {k: _rounded(v, 4) for k, v in self.err_base_mm.items()},
                "used": _rounded(self.used, 0), "t_s": None if self.t_s is None else _rounded(self.t_s, 3)}

    def _columns(self, rows: slice = slice(None)) -> tuple[list[str], np.ndarray]:
        n = self.q_deg.shape[1]
        names = ["used", "t_s", *(f"q{j + 1}" for j in range(n)), "x", "y", "z"]
        t_s = self.t_s[rows] if self.t_s is not None else np.full(len(self.used[rows]), np.nan)
        blocks = [self.used[rows, None], t_s[:, None], np.round(self.q_deg[rows], 4), np.round(self.p_base_mm[rows], 4)]
        for stage, e in self.err_base_mm.items():
            names += [f"{stage}_ex", f"{stage}_ey", f"{stage}_ez"]
            blocks.append(np.round(e[rows], 4))
        if self.pred_std_mm is not None:
            names.append("pred_std_mm")
            blocks.append(np.round(self.pred_std_mm[rows], 6)[:, None])
        return names, np.hstack(blocks)

    def reference(self) -> dict:
        """report.json's ``points`` value when the rows are in points.csv."""
        return {"file": POINTS_FILE, "format": POINTS_FORMAT, "n": len(self),
                "columns": ["set", *self._columns(slice(0))[0], "point_id"], "t_s": self.t_s is not None,
                "stages": list(self.err_base_mm)}

    def write_csv(self, path: str | Path) -> Path:
        """points.csv (atomic): header, then one row per point (a formatted line per row: no per-value calls),
        formatted ``CSV_ROWS`` rows at a time."""
        names = self._columns(slice(0))[0]
        fmt = ",".join(["%.10g"] * len(names))
        ids = [neutralise(pid) for pid in self.point_id]               # spreadsheet-safe text cells
        if any(c in "\x00".join(ids) for c in ',"\r\n'):              # quote only when some id needs it
            ids = [_csv_text(pid) for pid in ids]
        parts = [(",".join(["set", *names, "point_id"]) + "\n").encode()]
        for start in range(0, len(self), CSV_ROWS):
            b = slice(start, start + CSV_ROWS)
            parts.append("".join(f"{s},{fmt % tuple(row)},{pid}\n" for s, row, pid in
                                 zip(self.set[b], self._columns(b)[1].tolist(), ids[b])).encode())
        return atomic_write(path, b"".join(parts))

    @classmethod
    def read_csv(cls, path: str | Path, ref: Mapping) -> "PointTable":
        """The table a ``reference()`` points at (DataError when the file is missing or does not match it), read
        ``CSV_ROWS`` lines at a time."""
        cols = list(ref["columns"])
        head, values, body = None, [], []
        try:
            with open(path, newline="") as f:
                head = f.readline()
                while lines := _records(f):
                    values.append(np.loadtxt(lines, delimiter=",", usecols=range(1, len(cols) - 1), quotechar='"',
                                             dtype=float, ndmin=2))
                    body += _set_and_id(lines)
        except OSError as exc:
            raise DataError(str(path), f"cannot read the report's per-point file: {exc.strerror}") from None
        except ValueError:
            raise DataError(str(path), "a value is not a number") from None
        values = np.concatenate(values) if values else np.zeros((0, len(cols) - 2))
        header = next(csv.reader([head])) if head and '"' in head else (head or "").rstrip("\r\n").split(",")
        if not head or header != cols or len(body) != int(ref["n"]) or len(values) != len(body):
            raise DataError(str(path), f"does not match report.json (expected {ref['n']} rows of {cols})")
        names = cols[1:-1]
        at = {c: i for i, c in enumerate(names)}
        nq = sum(1 for c in names if c[0] == "q" and c[1:].isdigit())
        err = {s: values[:, [at[f"{s}_ex"], at[f"{s}_ey"], at[f"{s}_ez"]]] for s in ref["stages"]}
        return cls(tuple(restore(r[-1]) for r in body), tuple(r[0] for r in body), values[:, at["q1"]:at["q1"] + nq],
                   values[:, [at["x"], at["y"], at["z"]]], err, values[:, at["used"]],
                   values[:, at["t_s"]] if ref.get("t_s") else None,
                   values[:, at["pred_std_mm"]] if "pred_std_mm" in at else None)

    @classmethod
    def of(cls, points, directory: str | Path | None = None) -> "PointTable | None":
        """The table of report.json's ``points`` value: inline dict, side-file reference (read from
        ``directory``) or already a table; None when absent."""
        if points is None or isinstance(points, cls):
            return points
        if "file" in points:
            if directory is None:
                raise DataError(POINTS_FILE, "the report's per-point rows are in a side file: give its directory")
            return cls.read_csv(Path(directory) / Path(points["file"]).name, points)
        arr = lambda rows: np.array(rows, dtype=float) if len(rows) else np.zeros((0, 3))  # noqa: E731 (None -> nan)
        n = len(points["point_id"])
        used = points.get("used")                                   # absent from reports of older versions
        return cls(tuple(points["point_id"]), tuple(points["set"]), arr(points["q_deg"]), arr(points["p_base_mm"]),
                   {k: arr(v) for k, v in points["err_base_mm"].items()},
                   np.full(n, np.nan) if used is None else np.array(used, dtype=float),
                   None if points.get("t_s") is None else np.array(points["t_s"], dtype=float))


def point_table(point_ids, sets, q_deg: np.ndarray, p_tracker_mm: np.ndarray, T_tracker_base: np.ndarray,
                predictions_tracker_mm: Mapping[str, Callable[[np.ndarray], np.ndarray]], used: np.ndarray,
                t_s: np.ndarray | None = None, pred_std_mm: np.ndarray | None = None) -> PointTable:
    """The per-point table (``report_points_value`` gives report.json's ``points``).

    ``predictions_tracker_mm[stage](rows)`` -> predicted SMR positions (len(rows), 3) mm in the tracker frame for
    row indices ``rows``; ``used`` (N,): 1 = the row is in the fit, 0 = an excluded calib row, NaN = not a calib
    row; ``pred_std_mm`` (N,) the GPR predictive std of test rows (NaN elsewhere), kept in the side file."""
    q = np.asarray(q_deg, float)
    has_q = np.all(np.isfinite(q), axis=1)
    rows = np.flatnonzero(has_q)
    T = np.asarray(T_tracker_base, float)
    R = T[:3, :3]
    p_base = (np.asarray(p_tracker_mm, float) - T[:3, 3]) @ R          # R^T (p - t), row-wise
    err = {}
    for stage, predict in predictions_tracker_mm.items():
        e = np.full((len(q), 3), np.nan)
        e[rows] = (p_tracker_mm[rows] - predict(rows)) @ R
        err[stage] = e
    return PointTable(tuple(point_ids), tuple(sets), q, p_base, err, np.asarray(used, float),
                      None if t_s is None else np.asarray(t_s, float),
                      None if pred_std_mm is None else np.asarray(pred_std_mm, float))


def report_points_value(table: PointTable) -> dict:
    """report.json's ``points``: the inline table up to ``POINTS_INLINE_MAX`` rows, else the side-file reference
    (``write_outputs`` writes the file)."""
    return table.to_json() if len(table) <= POINTS_INLINE_MAX else table.reference()


def _records(f) -> list[str]:
    """The next ``CSV_ROWS`` lines of ``f``, and more until no quoted cell is left open (an id with a line break)."""
    lines = list(itertools.islice(f, CSV_ROWS))
    while sum(ln.count('"') for ln in lines) % 2 and (more := f.readline()):
        lines.append(more)
    return lines


def _set_and_id(lines: list[str]) -> list[list[str]]:
    """[set, point_id] of data lines of points.csv (only the first and the last cell are text; the csv module's
    parser when an id is quoted)."""
    if any('"' in ln for ln in lines):
        return [[r[0], r[-1]] for r in csv.reader(lines) if r]
    return [[ln.split(",", 1)[0], ln.rsplit(",", 1)[-1].rstrip("\r\n")] for ln in lines if ln.strip("\r\n")]


def _csv_text(text: str) -> str:
    """A CSV text cell: quoted (quotes doubled) when it holds a separator, a quote or a line break."""
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if any(c in text for c in ',"\r\n') else text


def _rounded(a: np.ndarray, decimals: int) -> list:
    """Nested lists with NaN -> None (strict JSON)."""
    a = np.round(np.asarray(a, float), decimals)
    obj = a.astype(object)
    obj[~np.isfinite(a)] = None
    return obj.tolist()


def cell_summary(cfg) -> dict:
    """Cell identification and config summary for the report (from the campaign config)."""
    r, t, g = cfg.robot, cfg.tracker, cfg.plan.grid
    return {"robot_model": r.model, "robot_url": r.url, "convention": r.convention, "n_joints": len(r.joints),
            "hayati_joints": list(r.hayati_joints), "repeatability_mm": r.repeatability_mm,
            "tracker_model": t.model, "tracker_url": t.url, "p_flange_smr_mm": list(cfg.tool.p_flange_smr_mm),
            "payload_kg": cfg.tool.payload_kg, "grid_center_mm": list(g.center_mm), "grid_size_mm": list(g.size_mm),
            "grid_step_mm": g.step_mm}
