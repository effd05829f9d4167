"""Tests of the interchange CSV (campaign/data/interchange_csv.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from campaign.errors import DataError
from campaign.data.dataset import Dataset
from campaign.data import interchange_blocks
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.data.log_dataset import dataset_from_log
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import read_log


HEADER6 = "point_id,set,q1,q2,q3,q4,q5,q6,x,y,z"
ROWS6 = [
    "P1,calib,0,10,20,30,40,50,1000.5,200.25,300.125",
    "P2,calib,5,10,15,30,45,50,1001.5,201.25,301.125",
    "P3,test,-5,12,15,30,40,50.5,1002.5,202.25,302.125",
]


def write(tmp_path: Path, text: str | bytes, name: str = "data.csv") -> Path:
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    return path


def random_dataset(rng: np.random.Generator, n_rows: int, n_joints: int, **optional) -> Dataset:
    sets = rng.choice(["calib", "test"], n_rows)
    return Dataset(
        point_id=tuple(f"P{i}" for i in range(n_rows)),
        set=tuple(sets),
        q_deg=rng.uniform(-180, 180, (n_rows, n_joints)),
        p_tracker_mm=rng.uniform(-3000, 3000, (n_rows, 3)),
        source="random",
        **optional,
    )


def assert_same(a: Dataset, b: Dataset) -> None:
    assert a.point_id == b.point_id and a.set == b.set
    for name in ("q_deg", "p_tracker_mm", "t_s", "temp_c", "payload_kg", "p2_tracker_mm", "p3_tracker_mm"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name  # bit-identical, not just close


# ---------------------------------------------------------------- good input


@pytest.mark.unit
def test_read_simple_6_joint_file(tmp_path):
    path = write(tmp_path, "\n".join([HEADER6, *ROWS6]) + "\n")
    ds = read_csv(path)
    assert len(ds) == 3 and ds.n_joints == 6
    assert ds.point_id == ("P1", "P2", "P3") and ds.set == ("calib", "calib", "test")
    assert ds.q_deg.shape == (3, 6) and ds.q_deg[2, 5] == 50.5
    np.testing.assert_array_equal(ds.p_tracker_mm[0], [1000.5, 200.25, 300.125])
    assert ds.t_s is None and ds.temp_c is None and ds.p2_tracker_mm is None and ds.sigma_mm is None
    assert ds.source == str(path)
    np.testing.assert_array_equal(ds.mask("calib"), [True, True, False])
    test = ds.subset(ds.mask("test"))
    assert test.point_id == ("P3",) and test.q_deg.shape == (1, 6)


@pytest.mark.unit
def test_read_7_joint_file_any_column_order(tmp_path):
    header = "x,y,z,Q7,q6,q5,q4,q3,q2,q1,SET,point_id,temp_c"
    row = "1,2,3,7,6,5,4,3,2,1,Calib,A,20.5"
    ds = read_csv(write(tmp_path, f"{header}\n{row}\n"))
    assert ds.n_joints == 7
    np.testing.assert_array_equal(ds.q_deg[0], [1, 2, 3, 4, 5, 6, 7])
    np.testing.assert_array_equal(ds.p_tracker_mm[0], [1, 2, 3])
    assert ds.set == ("calib",) and ds.temp_c.tolist() == [20.5]


@pytest.mark.unit
def test_semicolon_separator_with_decimal_comma(tmp_path):
    text = "point_id;set;q1;q2;x;y;z;t_s\nA;calib;1,5;-2;10,25;0;1e3;0\nB;test;2.5;3;11;1;2;1,5\n"
    ds = read_csv(write(tmp_path, text))
    np.testing.assert_array_equal(ds.q_deg, [[1.5, -2.0], [2.5, 3.0]])
    np.testing.assert_array_equal(ds.p_tracker_mm[0], [10.25, 0.0, 1000.0])
    np.testing.assert_array_equal(ds.t_s, [0.0, 1.5])


@pytest.mark.unit
def test_bom_comments_blank_lines_crlf_whitespace_quotes(tmp_path):
    text = (
        "\ufeff# exported by some tracker software\r\n"
        "\r\n"
        f"{HEADER6}\r\n"
        "# calib points\r\n"
        f"{ROWS6[0]}\r\n"
        "   \r\n"
        ' "P2" , calib , 5,10,15,30,45,50,1001.5,201.25,301.125\r\n'
        "  # an indented comment\r\n"
        f"{ROWS6[2]}"  # no final newline
    )
    ds = read_csv(write(tmp_path, text))
    assert ds.point_id == ("P1", "P2", "P3")
    assert ds.q_deg[1, 0] == 5.0


@pytest.mark.unit
def test_second_and_third_smr_and_scalars(tmp_path):
    header = HEADER6 + ",x2,y2,z2,x3,y3,z3,t_s,temp_c,payload_kg"
    row = ROWS6[0] + ",1,2,3,4,5,6,0.5,21.0,12"
    ds = read_csv(write(tmp_path, f"{header}\n{row}\n"))
    np.testing.assert_array_equal(ds.p2_tracker_mm, [[1, 2, 3]])
    np.testing.assert_array_equal(ds.p3_tracker_mm, [[4, 5, 6]])
    assert (ds.t_s[0], ds.temp_c[0], ds.payload_kg[0]) == (0.5, 21.0, 12.0)


@pytest.mark.unit
def test_check_rows_may_repeat_their_id(tmp_path):
    rows = [ROWS6[0], "C1,check,0,0,0,0,0,0,1,2,3", ROWS6[1], "C1,check,0,0,0,0,0,0,1,2,3.01"]
    ds = read_csv(write(tmp_path, "\n".join([HEADER6, *rows])))
    assert ds.point_id.count("C1") == 2 and ds.mask("check").sum() == 2


@pytest.mark.unit
@pytest.mark.parametrize("n_joints", [6, 7])
def test_round_trip_write_read(tmp_path, n_joints):
    rng = np.random.default_rng(n_joints)
    n = 200
    ds = random_dataset(
        rng,
        n,
        n_joints,
        t_s=np.cumsum(rng.uniform(0.1, 5.0, n)),
        temp_c=20 + rng.normal(size=n),
        payload_kg=np.full(n, 12.5),
        p2_tracker_mm=rng.normal(size=(n, 3)) * 1e3,
        p3_tracker_mm=rng.normal(size=(n, 3)) * 1e-7,  # tiny values: still exact
        sigma_mm=np.full(n, 0.01),
    )
    path = tmp_path / "rt.csv"
    write_csv(path, ds)
    back = read_csv(path)
    assert_same(ds, back)
    assert back.sigma_mm is None  # not part of the CSV format
    assert path.read_text().splitlines()[0] == (
        "point_id,set," + ",".join(f"q{k}" for k in range(1, n_joints + 1))
        + ",x,y,z,x2,y2,z2,x3,y3,z3,t_s,temp_c,payload_kg"
    )
    write_csv(path, back)  # overwriting is fine
    assert_same(ds, read_csv(path))


@pytest.mark.unit
def test_write_refuses_unreadable_data(tmp_path):
    rng = np.random.default_rng(1)
    ds = random_dataset(rng, 3, 6)
    bad_id = Dataset(("P1", "#P2", "P3"), ds.set, ds.q_deg, ds.p_tracker_mm)
    with pytest.raises(DataError, match="cannot be written"):
        write_csv(tmp_path / "a.csv", bad_id)
    q = ds.q_deg.copy()
    q[1, 2] = np.nan
    with pytest.raises(DataError, match="row 2: non-finite"):
        write_csv(tmp_path / "a.csv", Dataset(ds.point_id, ds.set, q, ds.p_tracker_mm))
    assert not list(tmp_path.iterdir())  # nothing left behind


@pytest.mark.system
def test_large_file_round_trips(tmp_path):
    """100k rows (timing: bench/bench_io.py)."""
    rng = np.random.default_rng(7)
    n = 100_000
    ds = random_dataset(rng, n, 6, t_s=np.arange(n) * 2.0, temp_c=20 + rng.normal(size=n))
    path = tmp_path / "big.csv"
    write_csv(path, ds)
    assert_same(ds, read_csv(path))


# ---------------------------------------------------------------- approach


@pytest.mark.unit
def test_approach_sign_hand_made_sequence():
    q = np.array(
        [
            [0.0, 5.0],
            [1.0, 5.0],  # j1 up; j2 has not moved yet
            [1.0, 4.0],  # j1 still: keeps +; j2 down
            [0.5, 4.0],  # j1 down; j2 still: keeps -
            [0.5, 4.0],  # nothing moves: both keep
            [2.0, 6.0],  # both up
        ]
    )
    ds = Dataset(tuple("ABCDEF"), ("calib",) * 6, q, np.zeros((6, 3)))
    expected = [[0, 0], [1, 0], [1, -1], [-1, -1], [-1, -1], [1, 1]]
    np.testing.assert_array_equal(ds.approach_sign(), expected)
    np.testing.assert_array_equal(ds.approach_sign(tol_deg=0.75)[:, 0], [0, 1, 1, 1, 1, 1])
    single = Dataset(("A",), ("test",), [[1.0, 2.0, 3.0]], [[0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(single.approach_sign(), [[0, 0, 0]])


@pytest.mark.unit
def test_dataset_is_validated_and_read_only():
    with pytest.raises(ValueError, match="p_tracker_mm"):
        Dataset(("A",), ("calib",), [[1.0]], [[1.0, 2.0]])
    with pytest.raises(ValueError, match="unknown set"):
        Dataset(("A",), ("train",), [[1.0]], [[1.0, 2.0, 3.0]])
    ds = Dataset(("A",), ("calib",), [[1.0]], [[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError):
        ds.q_deg[0, 0] = 2.0
    with pytest.raises(ValueError):
        ds.mask("train")


# ---------------------------------------------------------------- bad input

GOOD = [HEADER6, *ROWS6]


def replace_line(lines: list[str], index: int, text: str) -> str:
    out = list(lines)
    out[index] = text
    return "\n".join(out) + "\n"


BAD_CASES = {
    "not_a_number": (
        replace_line(GOOD, 2, "P2,calib,5,10,abc,30,45,50,1001.5,201.25,301.125"),
        "line 3, column 'q3': expected a number, got 'abc'",
    ),
    "empty_cell": (
        replace_line(GOOD, 3, "P3,test,-5,12,15,30,40,50.5,1002.5,,302.125"),
        "line 4, column 'y': expected a number, got ''",
    ),
    "nan": (
        replace_line(GOOD, 1, "P1,calib,0,10,20,30,40,50,NaN,200.25,300.125"),
        "line 2, column 'x': expected a finite number, got 'NaN'",
    ),
    "inf": (
        replace_line(GOOD, 1, "P1,calib,0,10,20,30,40,-inf,1000.5,200.25,300.125"),
        "line 2, column 'q6': expected a finite number, got '-inf'",
    ),
    "overflow": (
        replace_line(GOOD, 1, "P1,calib,0,10,20,30,40,50,1e999,200.25,300.125"),
        "line 2, column 'x': number out of range: '1e999'",
    ),
    "underscore_number": (
        replace_line(GOOD, 1, "P1,calib,1_000,10,20,30,40,50,1000.5,200.25,300.125"),
        "line 2, column 'q1': expected a number, got '1_000'",
    ),
    "missing_column": (
        "point_id,set,q1,q2,q4,q5,q6,x,y,z\nP1,calib,1,2,4,5,6,1,2,3\n",
        "header: missing column 'q3'",
    ),
    "missing_set_column": ("point_id,q1,x,y,z\nP1,1,1,2,3\n", "header: missing column 'set'"),
    "unknown_column": (HEADER6 + ",colour\n" + ROWS6[0] + ",red\n", "header: unknown column 'colour'"),
    "duplicate_column": (HEADER6 + ",x\n" + ROWS6[0] + ",1\n", "header: duplicate column 'x'"),
    "empty_column_name": (HEADER6 + ",\n" + ROWS6[0] + ",\n", "header: empty column name at position 12"),
    "y2_without_x2": (
        HEADER6 + ",y2,z2\n" + ROWS6[0] + ",1,2\n",
        "line 1, column 'x2': header: missing column 'x2' (needed with 'y2')",
    ),
    "third_smr_without_second": (
        HEADER6 + ",x3,y3,z3\n" + ROWS6[0] + ",1,2,3\n",
        "line 1, column 'x2': header: missing column 'x2' (x3,y3,z3 need x2,y2,z2)",
    ),
    "duplicate_point_id": (
        replace_line(GOOD + ["P4,test,0,0,0,0,0,0,0,0,0"], 3, "P1,test,0,0,0,0,0,0,0,0,0"),
        "line 4: duplicate point_id 'P1' (first on line 2)",
    ),
    "check_reuses_calib_id": (
        "\n".join(GOOD + ["P2,check,0,0,0,0,0,0,0,0,0"]),
        "line 5: duplicate point_id 'P2' (first on line 3)",
    ),
    "empty_point_id": (replace_line(GOOD, 1, ",calib,0,10,20,30,40,50,1,2,3"), "line 2: point_id is empty"),
    "point_id_over_256_characters": (
        replace_line(GOOD, 2, "P" * 257 + ",calib,5,10,15,30,45,50,1001.5,201.25,301.125"),
        f"line 3: point_id {'P' * 40!r}... is 257 characters long (at most 256)",
    ),
    "too_few_fields": (
        replace_line(GOOD, 2, "P2,calib,5,10,15,30,45,50,1001.5,201.25"),
        "line 3: expected 11 fields, got 10",
    ),
    "too_many_fields": (replace_line(GOOD, 3, ROWS6[2] + ",7"), "line 4: expected 11 fields, got 12"),
    "bad_set": (
        replace_line(GOOD, 2, "P2,train,5,10,15,30,45,50,1001.5,201.25,301.125"),
        "line 3, column 'set': expected calib, test, check or nest, got 'train'",
    ),
    "header_only": ("# comment\n" + HEADER6 + "\n\n# nothing else\n", "no data rows"),
    "empty_file": ("", "no data rows (empty file, no header)"),
    "not_utf8": (
        (HEADER6 + "\n" + ROWS6[0] + "\nP\xe9,calib\n").encode("latin-1"),
        "line 3: not valid UTF-8 text",
    ),
}


@pytest.mark.unit
@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_gives_one_line_data_error(tmp_path, case):
    text, expected = BAD_CASES[case]
    path = write(tmp_path, text)
    with pytest.raises(DataError) as info:
        read_csv(path)
    message = str(info.value)
    assert message == f"{path}: {expected}"
    assert "\n" not in message
    assert isinstance(info.value, ValueError)


@pytest.mark.unit
def test_a_point_id_of_256_characters_is_read(tmp_path):
    path = write(tmp_path, replace_line(GOOD, 2, "P" * 256 + ",calib,5,10,15,30,45,50,1001.5,201.25,301.125"))
    assert read_csv(path).point_id[1] == "P" * 256


@pytest.mark.unit
def test_errors_report_the_physical_line_number(tmp_path):
    text = "# c1\n\n" + HEADER6 + "\n# c2\n" + ROWS6[0] + "\n\nP2,calib,5,10,15,30,45,50,x,1,2\n"
    path = write(tmp_path, text)
    with pytest.raises(DataError, match=r"line 7, column 'x': expected a number, got 'x'"):
        read_csv(path)


# ---------------------------------------------------------------- from a log


@pytest.mark.unit
def test_dataset_from_log(tmp_path):
    start = {"config_sha256": "0" * 64, "plan_sha256": "1" * 64, "config": {}, "created_utc": "t",
             "software_version": "test", "units": {}}
    with RunLog.create(tmp_path, start) as log:
        for i in range(3):
            log.append_point(
                {
                    "point_id": f"P{i}",
                    "set": "calib" if i < 2 else "test",
                    "kind": "plan",
                    "q_cmd_deg": [float(i)] * 6,
                    "q_read_deg": [i + 0.001] * 6,
                    "p_tracker_mm": [1000.0 + i, 0.0, 500.0],
                    "cov_mm2": np.diag([1e-4, 4e-4, 4e-4]),
                    "t_start_s": 100.0 + 10 * i,
                    "t_end_s": 102.0 + 10 * i,
                    "temperatures": {"temp_c": 20.0 + i, "base_c": 19.0},
                    "payload_kg": 5.0,
                }
            )
            log.append_point(
                {"point_id": "C0", "kind": "check", "q_cmd_deg": [9.0] * 6, "p_tracker_mm": [1.0, 2.0, 3.0],
                 "sigma_mm": 0.02, "t_end_s": 105.0 + 10 * i, "temp_c": 21.0, "payload_kg": 5.0}
            )
    ds = dataset_from_log(read_log(tmp_path))
    assert ds.point_id == ("P0", "C0", "P1", "C0", "P2", "C0")
    assert ds.set == ("calib", "check", "calib", "check", "test", "check")
    np.testing.assert_array_equal(ds.q_deg[0], [0.001] * 6)  # q_read_deg preferred
    np.testing.assert_array_equal(ds.q_deg[1], [9.0] * 6)  # q_cmd_deg as fallback
    np.testing.assert_allclose(ds.t_s, [0, 3, 10, 13, 20, 23])
    np.testing.assert_array_equal(ds.temp_c, [20, 21, 21, 21, 22, 21])
    np.testing.assert_allclose(ds.sigma_mm[0], 0.017320508075688773)  # sqrt(trace/3)
    assert ds.sigma_mm[1] == 0.02
    assert ds.source.endswith("log.jsonl")
    write_csv(tmp_path / "out.csv", ds)  # repeated check ids survive the CSV round trip
    assert_same(ds, read_csv(tmp_path / "out.csv"))


@pytest.mark.unit
def test_dataset_from_log_rejects_mixed_optional_fields(tmp_path):
    start = {"units": {}}
    with RunLog.create(tmp_path, start) as log:
        base = {"set": "calib", "q_cmd_deg": [0.0], "p_tracker_mm": [0, 0, 0]}
        log.append_point({**base, "point_id": "A", "t_end_s": 1})
        log.append_point({**base, "point_id": "B"})
    with pytest.raises(DataError, match=r"point record 2 \(point_id 'B'\): has no 't_s'"):
        dataset_from_log(read_log(tmp_path))


@pytest.mark.unit
def test_a_subset_keeps_each_rows_place_in_the_measurement_order_through_the_csv(tmp_path):
    """A subset of ``Dataset.with_order_context`` carries the approach signs and last moves of the full order (not
    those of the subset's own neighbours), ``write_csv`` writes them as the order columns and ``read_csv`` reads
    them back bit for bit; a plain subset carries none."""
    q = np.array([[0.0, 5.0], [1.0, 5.0], [1.0, 4.0], [0.5, 4.0], [0.5, 4.0], [2.0, 6.0]])
    ds = Dataset(tuple("ABCDEF"), ("calib",) * 6, q, np.zeros((6, 3)))
    assert ds.subset(np.array([True, False, False, True, False, True])).order_context is None
    sub = ds.with_order_context().subset(np.array([True, False, False, True, False, True]))
    c = sub.order_context
    np.testing.assert_array_equal(c.approach, ds.approach_sign()[[0, 3, 5]])
    np.testing.assert_allclose(np.degrees(c.move_rad), [[0, 0], [-0.5, 0], [1.5, 2]])
    np.testing.assert_allclose(np.degrees(c.prev_move_rad), [[0, 0], [0, -1], [0, 0]])
    np.testing.assert_array_equal(c.order, [0, 3, 5])
    np.testing.assert_array_equal(sub.subset(np.array([False, True, True])).order_context.order, [3, 5])
    path = tmp_path / "sub.csv"
    write_csv(path, sub)
    assert path.read_text().splitlines()[0].endswith(
        "approach1,approach2,move1,move2,move_before1,move_before2,order")
    back = read_csv(path)
    assert_same(back, sub)
    for name in ("approach", "move_rad", "prev_move_rad", "order"):
        np.testing.assert_allclose(getattr(back.order_context, name), getattr(c, name), rtol=1e-15, atol=1e-18)
    plain = HEADER6 + "\n" + "\n".join(ROWS6) + "\n"
    assert read_csv(write(tmp_path, plain, "plain.csv")).order_context is None


@pytest.mark.unit
@pytest.mark.parametrize("header, expected", [
    ("approach1,approach2", "header: missing column 'approach3' (the order columns approach1.., move1.., "
                            "move_before1.., order come together)"),
    ("approach7", "header: 'approach7' but 6 joint columns q1..q6"),
    ("approach1..6=2", "line 2, column 'approach1': approach1 2: an approach is -1, 0 or +1"),
    ("order=3,1,2", "line 3, column 'order': order goes back (1 after 3): rows must be in measurement order"),
])
def test_order_columns_come_complete(tmp_path, header, expected):
    if "=" in header:                                   # a complete group with one bad value
        full = ",".join(f"{g}{k}" for g in ("approach", "move", "move_before") for k in range(1, 7)) + ",order"
        orders = header.split("=")[1].split(",") if header.startswith("order") else ["0", "1", "2"]
        first = header.split("=")[1] if header.startswith("approach") else "0"
        rows = [r + "," + ",".join([first if i == 0 else "0"] + ["0"] * 17) + "," + o for i, (r, o) in
                enumerate(zip(ROWS6, orders))]
        text = HEADER6 + "," + full + "\n" + "\n".join(rows) + "\n"
    else:
        extra = header.count(",") + 1
        text = HEADER6 + "," + header + "\n" + "\n".join(r + ",0" * extra for r in ROWS6) + "\n"
    with pytest.raises(DataError) as info:
        read_csv(write(tmp_path, text))
    assert expected in str(info.value) and "\n" not in str(info.value)


@pytest.mark.unit
def test_order_context_skips_nest_readings_as_the_calibration_does(tmp_path):
    """A nest reading (no joints) between two robot rows: the robot row after it gets its move from the robot row
    before the nest, as the calibration computes it once nest rows are set aside; the nest row's moves are unknown
    (written empty, read back as NaN)."""
    q = np.array([[0.0, 0.0], [1.0, 2.0], [np.nan, np.nan], [3.0, 1.0]])
    ds = Dataset(("A", "B", "N1", "C"), ("calib", "calib", "nest", "test"), q, np.ones((4, 3)),
                 t_s=[0.0, 1.0, 2.0, 3.0], nest_id=("", "", "N1", ""))
    c = ds.with_order_context().order_context
    np.testing.assert_allclose(np.degrees(c.move_rad[[1, 3]]), [[1, 2], [2, -1]])
    assert np.isnan(c.move_rad[2]).all() and (c.approach[2] == 0).all()
    np.testing.assert_array_equal(c.order, [0, 1, 1, 2])
    path = tmp_path / "nest.csv"
    write_csv(path, ds.with_order_context().subset(np.array([False, True, True, True])))
    back = read_csv(path).order_context
    np.testing.assert_allclose(np.degrees(back.move_rad[[0, 2]]), [[1, 2], [2, -1]])
    assert np.isnan(back.move_rad[1]).all()


# ---------------------------------------------------------------- read in blocks


@pytest.mark.unit
@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_blocks_of_a_few_lines_give_the_same_errors(tmp_path, monkeypatch, case):
    """The file is read a few lines at a time: every error is the whole-file one (line, column, message)."""
    monkeypatch.setattr(interchange_blocks, "READ_BYTES", 50)
    text, expected = BAD_CASES[case]
    path = write(tmp_path, text)
    with pytest.raises(DataError) as info:
        read_csv(path)
    assert str(info.value) == f"{path}: {expected}"


@pytest.mark.unit
def test_the_earliest_kind_of_problem_wins_across_blocks(tmp_path, monkeypatch):
    """Problems in several blocks: a whole-file read checks field counts before sets, sets before ids, ids before
    numbers, whatever their lines; read in blocks, the same problem is reported."""
    monkeypatch.setattr(interchange_blocks, "READ_BYTES", 60)
    rows = [f"P{i},calib,0,10,20,30,40,50,1,2,3" for i in range(40)]
    rows[3] = "P3,calib,0,10,20,30,40,50,1,2,x"              # number syntax
    rows[9] = "P1,calib,0,10,20,30,40,50,1,2,3"              # duplicate id
    rows[20] = "P20,train,0,10,20,30,40,50,1,2,3"            # bad set
    rows[30] = "P30,calib,0,10,20,30,40,50,1,2"              # field count
    cases = [(30, "line 32: expected 11 fields, got 10"),
             (20, "line 22, column 'set': expected calib, test, check or nest, got 'train'"),
             (9, "line 11: duplicate point_id 'P1' (first on line 3)"),
             (3, "line 5, column 'z': expected a number, got 'x'")]
    for fixed, expected in cases:
        path = write(tmp_path, "\n".join([HEADER6, *rows]) + "\n")
        with pytest.raises(DataError) as info:
            read_csv(path)
        assert str(info.value) == f"{path}: {expected}"
        rows[fixed] = f"P{fixed},calib,0,10,20,30,40,50,1,2,3"
    path = write(tmp_path, "\n".join([HEADER6, *rows]) + "\n")
    assert len(read_csv(path)) == 40


@pytest.mark.unit
def test_a_file_read_in_blocks_is_the_file_read_whole(tmp_path, monkeypatch):
    rng = np.random.default_rng(3)
    n = 300
    ds = random_dataset(rng, n, 6, t_s=np.arange(n) * 2.0, temp_c=20 + rng.normal(size=n))
    path = tmp_path / "rt.csv"
    write_csv(path, ds)
    whole = read_csv(path)
    monkeypatch.setattr(interchange_blocks, "READ_BYTES", 333)
    assert_same(whole, read_csv(path))
    assert_same(ds, whole)
