"""Hostile interchange CSVs (issue 12): ``reprocess`` and ``diagnose`` exit 2 with ONE stderr line naming the
file, never a traceback, and write nothing (no report.json, no model.json, no diagnosis JSON)."""
from __future__ import annotations

import csv
import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.campaign.helpers import read_report, small_config
from tests.campaign.hostile import assert_one_line, cli, snapshot

Rows = list[list[str]]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A finished small IRB 2600 run (48 calib rows): its data.csv rows and the configs."""
    from campaign.cli import main

    root = tmp_path_factory.mktemp("hostile-csv")
    cfg = small_config(root, "irb2600")
    other = small_config(root, "irb4600")
    assert main(["run", str(cfg), "--out", str(root / "run")]) == 0
    rows = list(csv.reader((root / "run" / "data.csv").read_text().splitlines()))
    return {"rows": rows, "config": cfg, "irb4600": other}


def col(rows: Rows, name: str) -> int:
    return rows[0].index(name)


def first(rows: Rows, set_name: str, k: int = 0) -> int:
    return [i for i, r in enumerate(rows) if i and r[1] == set_name][k]


def setcell(name: str, value: str, set_name: str = "calib", k: int = 2) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        rows[first(rows, set_name, k)][col(rows, name)] = value
        return rows
    return apply


def scale_xyz(factor: float) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        j = col(rows, "x")
        for r in rows[1:]:
            r[j:j + 3] = [repr(float(v) * factor) for v in r[j:j + 3]]
        return rows
    return apply


def map_q(fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        j = col(rows, "q1")
        q = np.array([[float(v) for v in r[j:j + 6]] for r in rows[1:]])
        for r, qq in zip(rows[1:], fn(q)):
            r[j:j + 6] = [repr(float(v)) for v in qq]
        return rows
    return apply


def drop_col(name: str) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        j = col(rows, name)
        return [r[:j] + r[j + 1:] for r in rows]
    return apply


def add_col(name: str, value: str) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        j = col(rows, "q6") + 1
        return [r[:j] + ([name] if i == 0 else [value]) + r[j:] for i, r in enumerate(rows)]
    return apply


def only_calib(n: int) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        keep = {id(r) for r in [r for r in rows[1:] if r[1] == "calib"][:n]}
        return [rows[0]] + [r for r in rows[1:] if r[1] != "calib" or id(r) in keep]     # measurement order kept
    return apply


def relabel(old: str, new: str) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        for r in rows[1:]:
            if r[1] == old:
                r[1] = new
        return rows
    return apply


def xyz(fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        j = col(rows, "x")
        p = np.array([[float(v) for v in r[j:j + 3]] for r in rows[1:]])
        for r, pp in zip(rows[1:], fn(p)):
            r[j:j + 3] = [repr(float(v)) for v in pp]
        return rows
    return apply


def header(fn: Callable[[list[str]], list[str]]) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        return [fn(list(rows[0]))] + rows[1:]
    return apply


def row_len(delta: int) -> Callable[[Rows], Rows]:
    def apply(rows: Rows) -> Rows:
        i = first(rows, "calib", 3)
        rows[i] = rows[i][:-1] if delta < 0 else rows[i] + ["1.0"]
        return rows
    return apply


def dup_id(rows: Rows) -> Rows:
    rows[first(rows, "calib", 5)][0] = rows[first(rows, "calib", 4)][0]
    return rows


@dataclass(frozen=True)
class Case:
    transform: Callable[[Rows], Rows] | None = None
    raw: bytes | None = None
    needles: tuple[str, ...] = ()
    config: str = "config"


RNG = np.random.default_rng(12)
CASES: dict[str, Case] = {
    "empty_file": Case(raw=b""),
    "header_only": Case(raw=b"point_id,set,q1,q2,q3,q4,q5,q6,x,y,z\n", needles=("no data rows",)),
    "binary_garbage": Case(raw=bytes(range(256)) * 4),
    "not_utf8": Case(raw=b"point_id,set,q1,q2,q3,q4,q5,q6,x,y,z\nA\xff,calib,0,0,0,0,0,0,1,2,3\n",
                     needles=("UTF-8",)),
    "unknown_column": Case(header(lambda h: [("tt" if c == "t_s" else c) for c in h]), needles=("tt",)),
    "missing_column_z": Case(drop_col("z"), needles=("'z'",)),
    "duplicate_column": Case(header(lambda h: [("x" if c == "y" else c) for c in h]), needles=("duplicate",)),
    "text_in_q1": Case(setcell("q1", "abc"), needles=("q1",)),
    "nan_in_x": Case(setcell("x", "nan"), needles=("x",)),
    "inf_in_y": Case(setcell("y", "inf"), needles=("y",)),
    "x_1e300": Case(setcell("x", "1e300"), needles=("line", "1e+300")),
    "empty_x_cell": Case(setcell("x", ""), needles=("x",)),
    "empty_set_cell": Case(setcell("set", ""), needles=("line",)),
    "q2_1000_deg": Case(setcell("q2", "1000"), needles=("line", "q2 = 1000", "--force")),
    "q1_minus_1e6": Case(setcell("q1", "-1e6"), needles=("line", "q1", "limits")),
    "xyz_in_metres": Case(scale_xyz(1e-3), needles=("look like m,",)),
    "xyz_in_cm": Case(scale_xyz(0.1), needles=("look like cm",)),
    "xyz_in_inches": Case(scale_xyz(1 / 25.4), needles=("look like inch",)),
    "xyz_in_micrometres": Case(scale_xyz(1e3), needles=("not a tracker reading",)),
    "xyz_scaled_by_3": Case(scale_xyz(3.0), needles=("scale does not match",)),
    "q_in_radians": Case(map_q(np.radians), needles=("belong to this robot",)),
    "q1_sign_flipped": Case(map_q(lambda q: q * np.array([-1, 1, 1, 1, 1, 1])), needles=("belong to this robot",)),
    "xyz_mirrored": Case(xyz(lambda p: p[:, [1, 0, 2]]), needles=("belong to this robot",)),
    "xyz_shifted_by_one_row": Case(xyz(lambda p: np.roll(p, 1, axis=0)), needles=("belong to this robot",)),
    "xyz_noise_50_mm": Case(xyz(lambda p: p + RNG.normal(0, 50, p.shape)), needles=("belong to this robot",)),
    "wrong_robot_config": Case(needles=("belong to this robot", "IRB 4600"), config="irb4600"),
    "five_joint_columns": Case(drop_col("q6"), needles=("5 joint columns",)),
    "seven_joint_columns": Case(add_col("q7", "0"), needles=("7 joint columns",)),
    "duplicate_point_id": Case(dup_id, needles=("duplicate",)),
    "empty_point_id": Case(setcell("point_id", ""), needles=("point_id",)),
    "unknown_set": Case(relabel("test", "train"), needles=("train",)),
    "five_calib_rows": Case(only_calib(5), needles=("calib rows",)),
    "no_calib_rows": Case(relabel("calib", "test"), needles=("calib rows",)),
    "short_row": Case(row_len(-1), needles=("fields",)),
    "long_row": Case(row_len(+1), needles=("fields",)),
    "all_xyz_identical": Case(xyz(lambda p: np.zeros_like(p) + 1000.0)),
    "all_poses_identical": Case(map_q(lambda q: np.zeros_like(q) + q[0])),
}


def _write(tmp: Path, base: dict, case: Case) -> Path:
    path = tmp / "data.csv"
    if case.raw is not None:
        path.write_bytes(case.raw)
    else:
        rows = [list(r) for r in base["rows"]]
        if case.transform is not None:
            rows = case.transform(rows)
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows(rows)
        path.write_text(buf.getvalue())
    return path


@pytest.mark.system
def test_table_size():
    assert len(CASES) >= 30


@pytest.mark.system
@pytest.mark.parametrize("name", sorted(CASES))
def test_hostile_csv(name, base, tmp_path, capsys):
    case = CASES[name]
    path = _write(tmp_path, base, case)
    config = base["config"] if case.config == "config" else base[case.config]
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "reprocess", path, "--config", config, "--out", tmp_path / "out")
    assert_one_line(code, out, err, 2, str(path), *case.needles)
    code, out, err = cli(capsys, "diagnose", path, "--config", config, "--json", tmp_path / "diag.json")
    assert_one_line(code, out, err, 2, str(path))
    assert snapshot(tmp_path) == before                 # no out/, no model.json, no diag.json


@pytest.mark.system
def test_force_overrides_and_the_report_says_so(base, tmp_path, capsys):
    import json

    path = _write(tmp_path, base, CASES["q2_1000_deg"])
    code, out, err = cli(capsys, "reprocess", path, "--config", base["config"], "--out", tmp_path / "out", "--force")
    assert code == 0, err
    assert "OVERRIDDEN with --force" in out and "q2 = 1000" in out
    plaus = read_report(tmp_path / "out").plausibility
    assert plaus.forced and len(plaus.rejected_rows) == 1 and "q2 = 1000" in plaus.overridden[0]


@pytest.mark.system
def test_reprocess_states_unit_and_nominal_bound(base, tmp_path, capsys):
    path = _write(tmp_path, base, Case())
    code, out, err = cli(capsys, "reprocess", path, "--config", base["config"], "--out", tmp_path / "out")
    assert code == 0, err
    assert "xyz unit: mm" in out and "plausible below" in out
