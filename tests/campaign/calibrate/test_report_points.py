"""Per-point rows of report.json (campaign/calibrate/report_points.py): inline up to a size, points.csv beyond, and every
reader (the HTML report, PointTable.of) gets the same rows either way."""

import numpy as np
import pytest

from campaign.calibrate import report_points as rp
from campaign.config.simulation import simulated_cell
from campaign.cli import main
from campaign.config.load import load_cell
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import write_csv
from campaign.calibrate.report_points import PointTable
from tests.campaign.helpers import read_report, small_config


def simulated_csv(cfg_path, path, n=240, seed=0):
    """A seeded campaign on the config's simulated cell: random joints mid-range, 80 % calib."""
    cell = load_cell(cfg_path)
    cfg = cell.config
    rng = np.random.default_rng(seed)
    lo = np.array([j.q_min_deg for j in cfg.robot.joints])
    hi = np.array([j.q_max_deg for j in cfg.robot.joints])
    q = rng.uniform(lo + 0.3 * (hi - lo), hi - 0.3 * (hi - lo), (n, len(lo)))
    p, _ = simulated_cell(cell).measure(np.radians(q), rng)
    ids = tuple(f"P{i}" if i % 50 else f"P{i} a'b" for i in range(n))
    sets = tuple(np.where(rng.random(n) < 0.8, "calib", "test"))
    write_csv(path, Dataset(ids, sets, q, p, t_s=np.arange(n) * 2.0))
    return path


@pytest.mark.system
def test_points_beyond_the_inline_size_go_to_points_csv_and_read_back_identically(tmp_path, monkeypatch):
    cfg = small_config(tmp_path, "irb2600", **{"calibration.residual": "gpr", "calibration.effects": "none"})
    csv = simulated_csv(cfg, tmp_path / "data.csv")
    assert main(["reprocess", str(csv), "--config", str(cfg), "--out", str(tmp_path / "inline")]) == 0
    monkeypatch.setattr(rp, "POINTS_INLINE_MAX", 100)
    assert main(["reprocess", str(csv), "--config", str(cfg), "--out", str(tmp_path / "side")]) == 0
    inline, side = read_report(tmp_path / "inline"), read_report(tmp_path / "side")
    assert "file" not in inline.points and not (tmp_path / "inline" / "points.csv").exists()
    ref = side.points
    assert ref["file"] == "points.csv" and ref["format"] == "campaign-points/1" and ref["n"] == 240
    a, b = PointTable.of(inline.points), PointTable.of(ref, tmp_path / "side")
    assert b.point_id == a.point_id and b.set == a.set and b.point_id[50] == "P50 a'b"
    for name in ("q_deg", "p_base_mm", "used", "t_s"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert list(b.err_base_mm) == list(a.err_base_mm)
    for stage in a.err_base_mm:
        np.testing.assert_allclose(b.err_base_mm[stage], a.err_base_mm[stage], atol=1e-12)
    std_inline = inline.final.test_pred_std_mm.per_point_mm
    assert side.final.test_pred_std_mm.per_point_mm == {"file": "points.csv", "column": "pred_std_mm"}
    test = np.array(b.set) == "test"
    assert len(std_inline) == test.sum() > 0 and a.pred_std_mm is None
    np.testing.assert_allclose(b.pred_std_mm[test], [std_inline[i] for i in np.array(b.point_id)[test]], atol=1e-6)
    assert np.isnan(b.pred_std_mm[~test]).all()
    figures = sorted(p.name for p in (tmp_path / "side" / "report_figures").glob("*.png"))
    assert figures and figures == sorted(p.name for p in (tmp_path / "inline" / "report_figures").glob("*.png"))
    assert (tmp_path / "side" / "report.html").read_text().count("<img") == \
        (tmp_path / "inline" / "report.html").read_text().count("<img")
    (tmp_path / "side" / "points.csv").unlink()             # a reader without the side file: one-line error
    assert main(["report", str(tmp_path / "side"), "--out", str(tmp_path / "again.html")]) == 2


@pytest.mark.unit
@pytest.mark.parametrize("rows", [rp.CSV_ROWS, 1, 2])
def test_point_ids_with_separators_quotes_and_line_breaks_round_trip(tmp_path, monkeypatch, rows):
    """Ids from a run log may hold any text: points.csv quotes them, the reader gets them back (also when the file
    is written and read a row or two at a time)."""
    monkeypatch.setattr(rp, "CSV_ROWS", rows)
    ids = ("a,b", 'say "hi"', "two\nlines", "plain", "=1+2")
    n = len(ids)
    q = np.arange(n * 6, dtype=float).reshape(n, 6)
    table = PointTable(ids, ("calib", "test", "check", "calib", "nest"), q, np.ones((n, 3)),
                       {"nominal": np.full((n, 3), 0.5)}, np.array([1.0, np.nan, np.nan, 0.0, np.nan]), None)
    table.write_csv(tmp_path / "points.csv")
    back = PointTable.of(table.reference(), tmp_path)
    assert back.point_id == ids and back.set == table.set and back.t_s is None
    np.testing.assert_array_equal(back.used, table.used)
    np.testing.assert_array_equal(back.q_deg, q)
