"""One record per number (issue 31) on a mock run of the demo cell (reduced plan, its real-cell phenomena on, so
physical effects are taken and the exported model is not the geometry-only fit): every identified parameter (value
and std) in the terminal, report.html, report.json, dh.csv, the RoboDK table and the URDF equals model.json, and
every "taken of tried" count equals report.json. The public UR5 campaign gets the same checks in
tests/campaign/test_ur5_public.py (one reprocess for both). ``-s`` prints what was checked."""
from __future__ import annotations

import json

import pytest

from tests.campaign.helpers import small_config
from tests.campaign.hostile import cli
from tests.campaign.one_record import check_everything

pytestmark = pytest.mark.system


def test_every_output_of_the_demo_prints_model_json(tmp_path, capsys):
    cfg = small_config(tmp_path, "irb2600", phenomena=True)
    out = tmp_path / "run"
    code, text, err = cli(capsys, "run", cfg, "--out", out)
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["parameters_fit"] == "geometry + physical effects" and report["parameters_geometry_only"]
    geo = {p["name"]: p for p in report["parameters_geometry_only"]}
    moved = [p["name"] for p in report["parameters"] if p["identified"] and p["delta"] != geo[p["name"]]["delta"]]
    assert moved                                     # the geometry-only fit differs: the table must show the export
    checked = check_everything(text, out, out / "config.yaml")
    with capsys.disabled():
        print(f"\ndemo (reduced plan): {checked}; {len(moved)} identified parameters differ from the geometry-only fit")
    assert checked["urdf chain max mm"] < 1e-9
