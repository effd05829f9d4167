"""Provenance: data that come without a run log say where they came from ("imported from FILE ...; devices not
recorded") in the CSV itself, the terminal, ``report.json`` and the HTML, and never name the config's devices; the
``# provenance:`` line of the interchange CSV round-trips as one line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.data.source import csv_provenance
from tests.campaign.helpers import ROOT, small_config
from tests.campaign.hostile import run_campaign_process

UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
DEVICES = ("mock://robot", "mock://tracker")            # configs/ur5.yaml's driver URLs: not the data's devices


def _dataset(provenance: str) -> Dataset:
    q = np.arange(12.0).reshape(2, 6)
    return Dataset(("P1", "P2"), ("calib", "test"), q, q[:, :3] * 10, source="mem", provenance=provenance)


@pytest.mark.unit
def test_the_provenance_line_round_trips_as_one_line(tmp_path):
    path = tmp_path / "d.csv"
    write_csv(path, _dataset("imported from a\nb.csv \x1b[31m(campaign import target-dif)"))
    first, header = path.read_text().splitlines()[:2]
    assert first == "# provenance: imported from a\\nb.csv \\x1b[31m(campaign import target-dif)"
    assert header.startswith("point_id,set,q1")
    assert read_csv(path).provenance == "imported from a\\nb.csv \\x1b[31m(campaign import target-dif)"
    write_csv(path, _dataset(""))
    assert path.read_text().startswith("point_id,") and read_csv(path).provenance == ""
    assert csv_provenance(read_csv(path)) == f"read from the interchange CSV {path}; devices not recorded"


@pytest.mark.system
def test_imported_data_say_where_they_came_from_and_name_no_device(tmp_path):
    """A part of the public UR5 campaign (the first 150 grid rows, the 20 random ones) through ``campaign import``
    and ``reprocess`` with configs/ur5.yaml, whose robot and tracker URLs are mock://."""
    calib, test = tmp_path / "grid.csv", tmp_path / "random.csv"
    calib.write_text("\n".join((UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv").read_text().splitlines()[:151]) + "\n")
    test.write_bytes((UR5 / "3D_UR5_uncalibrated_random_cleaned.csv").read_bytes())
    data, out = tmp_path / "data.csv", tmp_path / "out"
    code, _, err = run_campaign_process(["import", "target-dif", calib, test, "--out", data], tmp_path)
    assert code == 0, err
    origin = f"imported from {calib} (calib) and {test} (test) (campaign import target-dif)"
    assert data.read_text().splitlines()[0] == f"# provenance: {origin}"

    cfg = small_config(tmp_path, "ur5", **{"calibration.effects": "none", "calibration.residual": "none"})
    assert all(url in cfg.read_text() for url in DEVICES)
    code, text, err = run_campaign_process(["reprocess", data, "--config", cfg, "--out", out], tmp_path)
    assert code == 0, err
    line = f"{origin}; devices not recorded"
    assert " ".join(text.split()).startswith(f"{line}: whether they were simulated is not known")
    report_text = (out / "report.json").read_text()
    report = json.loads(report_text)
    assert report["provenance"] == report["summary"]["provenance"] == line
    assert report["cell"]["robot_url"] is None and report["cell"]["tracker_url"] is None
    html = (out / "report.html").read_text()
    assert f"Data {line}; no hash or time" in html and f'id="summary-origin">{line}' in html
    for device in DEVICES:
        assert device not in text and device not in report_text and device not in html, device

    subset = tmp_path / "subset.csv"                    # a subset says what it was chosen from, and its origin
    code, _, err = run_campaign_process(["select", data, "--config", cfg, "--points", 60, "--out", subset], tmp_path)
    assert code == 0, err
    assert read_csv(subset).provenance == f"80 of 170 rows selected from {data} (campaign select); {origin}"
