"""``campaign import target-dif``: the public UR5 campaign's layout -> interchange CSV, in measurement order."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from campaign.errors import DataError
from campaign.data.importers import DIF_SIGN, import_target_dif, read_target_dif_file
from campaign.data.interchange_csv import read_csv
from tests.campaign.hostile import assert_one_line, cli, snapshot

pytestmark = pytest.mark.unit

UR5 = Path(__file__).resolve().parents[2] / "data" / "serial_robots_datasets" / "UR5"
GRID, RANDOM = UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv", UR5 / "3D_UR5_uncalibrated_random_cleaned.csv"
HEADER = "step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif,joint_1,joint_2,joint_3,joint_4,joint_5,joint_6"


def test_the_public_campaign_imports_in_measurement_order():
    ds = import_target_dif(GRID, RANDOM)
    assert len(ds) == 1020 and ds.mask("calib").sum() == 1000 and ds.mask("test").sum() == 20
    assert ds.point_id[:2] == ("G000", "G001") and ds.point_id[1000:1002] == ("R00", "R01")
    raw = np.genfromtxt(GRID, delimiter=",", names=True)
    np.testing.assert_array_equal(ds.q_deg[:1000], np.c_[[raw[f"joint_{k}"] for k in range(1, 7)]].T)
    np.testing.assert_allclose(ds.p_tracker_mm[:1000, 0], raw["x_t"] + raw["x_dif"], rtol=0, atol=1e-12)


def test_the_dif_sign_is_the_one_that_restores_the_recorded_readings():
    """dif = reached - target: target + dif gives back the tracker readings, recorded with 6 decimals (mm), for every
    coordinate of both files; target - dif lands on that grid by chance only (about 0.2 % of the coordinates)."""
    assert DIF_SIGN == 1.0
    for path in (GRID, RANDOM):
        _, target, dif, _ = read_target_dif_file(path)
        for sign, share in ((1.0, 1.0), (-1.0, 0.0)):
            scaled = (target + sign * dif) * 1e6
            on_grid = np.mean(np.abs(scaled - np.round(scaled)) < 1e-3)
            assert on_grid == share if share == 1.0 else on_grid < 0.01


def test_rows_are_sorted_by_step_order(tmp_path):
    lines = GRID.read_text().splitlines()
    shuffled = tmp_path / "grid.csv"
    rng = np.random.default_rng(0)
    shuffled.write_text("\n".join([lines[0]] + [lines[1:][i] for i in rng.permutation(len(lines) - 1)]) + "\n")
    a, b = import_target_dif(GRID), import_target_dif(shuffled)
    assert a.point_id == b.point_id
    np.testing.assert_array_equal(a.q_deg, b.q_deg)
    np.testing.assert_array_equal(a.p_tracker_mm, b.p_tracker_mm)


def test_the_cli_writes_the_interchange_csv(tmp_path, capsys):
    out = tmp_path / "data.csv"
    code, text, err = cli(capsys, "import", "target-dif", GRID, RANDOM, "--out", out)
    assert code == 0, err
    assert "1000 calib + 20 test rows" in text and "target + dif" in text
    back, ref = read_csv(out), import_target_dif(GRID, RANDOM)
    assert back.point_id == ref.point_id and back.set == ref.set
    np.testing.assert_array_equal(back.p_tracker_mm, ref.p_tracker_mm)
    code, _, err = cli(capsys, "import", "target-dif", GRID, "--out", out, "--dif-sign", "-1")
    assert code == 2 and "--overwrite" in err                     # an existing file is not replaced silently
    code, _, err = cli(capsys, "import", "target-dif", GRID, "--out", out, "--dif-sign", "-1", "--overwrite")
    assert code == 0, err
    np.testing.assert_allclose(read_csv(out).p_tracker_mm, import_target_dif(GRID, dif_sign=-1.0).p_tracker_mm)


ROW = "0,1,2,3,0.1,0.2,0.3,10,20,30,40,50,60"
BAD = {
    "empty": ("", "empty file"),
    "header_only": (HEADER + "\n", "no data rows"),
    "missing_column": (HEADER.replace(",z_dif", "") + "\n" + ROW.replace(",0.3", "") + "\n", "'z_dif'"),
    "unknown_column": (HEADER + ",extra\n" + ROW + ",1\n", "'extra'"),
    "text_in_joint": (HEADER + "\n" + ROW.replace(",40,", ",abc,") + "\n", "line 2, column 'joint_4'"),
    "nan_in_dif": (HEADER + "\n" + ROW.replace(",0.2,", ",nan,") + "\n", "column 'y_dif'"),
    "short_row": (HEADER + "\n" + ROW.rsplit(",", 1)[0] + "\n", "line 2: expected 13 fields"),
    "fractional_step": (HEADER + "\n" + "0.5" + ROW[1:] + "\n", "step_order must be an integer"),
    "repeated_step": (HEADER + "\n" + ROW + "\n" + ROW + "\n", "step_order 0 appears twice"),
    "not_utf8": (b"step_order\xff\n", "UTF-8"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_files_are_one_line_exit_2_and_write_nothing(name, tmp_path, capsys):
    content, needle = BAD[name]
    path = tmp_path / "in.csv"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "import", "target-dif", path, "--out", tmp_path / "data.csv")
    assert_one_line(code, out, err, 2, str(path), needle)
    assert snapshot(tmp_path) == before
    with pytest.raises(DataError):
        import_target_dif(path)
