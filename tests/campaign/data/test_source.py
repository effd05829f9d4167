"""``load_source``: the one entry from a run directory (its log) or an interchange CSV to a dataset."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from campaign.data.interchange_csv import write_csv
from campaign.data.source import load_source
from campaign.errors import DataError
from campaign.run.log_writer import RunLog
from tests.campaign.run.test_records import point

pytestmark = pytest.mark.unit


def _run_dir(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    log = RunLog.create(run, {"config_sha256": "x"})
    for i in range(3):
        log.append_point(point(point_id=f"P{i}", p_tracker_mm=(1500.0 + i, -200.0, 800.0), t_end_s=4.0 + 10 * i))
    log.close()
    return run


def test_a_run_directory_gives_its_dataset_and_its_log(tmp_path):
    source = load_source(_run_dir(tmp_path))
    assert source.contents is not None and source.contents.start["config_sha256"] == "x"
    assert source.dataset.point_id == ("P0", "P1", "P2")
    np.testing.assert_allclose(source.dataset.t_s, [0.0, 10.0, 20.0])
    np.testing.assert_allclose(source.dataset.qc_deg[0], point().q_cmd_deg)      # read-back and commanded joints


def test_a_csv_gives_the_same_dataset_and_no_log(tmp_path):
    from_log = load_source(_run_dir(tmp_path)).dataset
    write_csv(tmp_path / "data.csv", from_log)
    source = load_source(tmp_path / "data.csv")
    assert source.contents is None and source.dataset.point_id == from_log.point_id
    np.testing.assert_allclose(source.dataset.q_deg, from_log.q_deg)
    np.testing.assert_allclose(source.dataset.p_tracker_mm, from_log.p_tracker_mm)


def test_a_missing_source_is_one_line_naming_it(tmp_path):
    with pytest.raises(DataError, match=r"nope\.csv: no such file or run directory"):
        load_source(tmp_path / "nope.csv")
