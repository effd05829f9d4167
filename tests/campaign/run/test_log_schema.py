"""One log schema (campaign/run/log_records.py): older and foreign point records migrated onto the typed records,
the rules a log's records obey together (``check_records``: one line naming file and line), the dataset built from
typed records only."""
from __future__ import annotations

import numpy as np
import pytest

from campaign.data.log_dataset import dataset_from_log
from campaign.errors import DataError
from campaign.io.json_fields import RecordError
from campaign.run.log_reader import LogContents, RunLogError
from campaign.run.log_records import NestRecord, PointRecord, check_records, migrate, point_from_dict

pytestmark = pytest.mark.unit

COV = [[1e-4, 0.0, 0.0], [0.0, 4e-4, 0.0], [0.0, 0.0, 4e-4]]


def foreign_point(i: int, **kw) -> dict:
    """A point of another tool's log: no runner bookkeeping (spread, samples, approach, retries...)."""
    return {"point_id": f"P{i}", "set": "calib", "q_cmd_deg": [float(i), 2.0], "p_tracker_mm": [1000.0 + i, 0.0, 5.0],
            "t_end_s": 100.0 + 10 * i, **kw}


def contents(records: list[dict]) -> LogContents:
    """A log holding ``records`` as its point records on lines 2, 3, ..."""
    return LogContents(start={}, points=records, path="log.jsonl", point_lines=list(range(2, 2 + len(records))))


def test_migrate_marks_a_kind_check_record_as_a_check_pose():
    old = {"point_id": "C0", "set": "calib", "kind": "check", "q_cmd_deg": [9.0, 1.0], "p_tracker_mm": [1, 2, 3]}
    assert migrate(old)["set"] == "check" and old["set"] == "calib"          # a copy: the log data is not touched
    assert point_from_dict(old, foreign=True).set == "check"
    ds = dataset_from_log(contents([foreign_point(0), foreign_point(1), {**old, "t_end_s": 130.0}]))
    assert ds.set == ("calib", "calib", "check")


def test_a_foreign_point_without_read_back_joints_uses_the_commanded_ones():
    rec = point_from_dict(foreign_point(3), foreign=True)
    assert isinstance(rec, PointRecord) and rec.q_read_deg is None and rec.q_cmd_deg == (3.0, 2.0)
    assert rec.spread_mm is None and rec.approach is None and rec.n_joints == 2
    ds = dataset_from_log(contents([foreign_point(0), foreign_point(1)]))
    np.testing.assert_array_equal(ds.q_deg, [[0.0, 2.0], [1.0, 2.0]])
    assert ds.qc_deg is None                                # no read-back: one joint set, the commanded one


def test_a_foreign_point_with_read_back_joints_only():
    data = foreign_point(4)
    data["q_read_deg"] = data.pop("q_cmd_deg")
    rec = point_from_dict(data, foreign=True)
    assert rec.q_cmd_deg is None and rec.q_read_deg == (4.0, 2.0) and rec.n_joints == 2
    with pytest.raises(RecordError, match="q_cmd_deg"):
        point_from_dict({k: v for k, v in data.items() if k != "q_read_deg"}, foreign=True)


def test_the_runners_log_is_read_strictly_and_a_foreign_one_leniently():
    data = foreign_point(0)
    with pytest.raises(RecordError, match="'q_read_deg'"):              # a field the runner always writes
        point_from_dict(data)
    with pytest.raises(RunLogError, match=r"^log\.jsonl: line 2: point record 'P0'"):
        contents([data]).records()
    assert contents([data]).records(foreign=True)[0].point_id == "P0"


def test_a_top_level_temp_c_and_sigma_mm_become_the_dataset_columns():
    recs = [foreign_point(i, temp_c=20.0 + i, sigma_mm=0.01 * (i + 1)) for i in range(3)]
    rec = point_from_dict(recs[0], foreign=True)
    assert rec.temp_c == 20.0 and rec.sigma_mm == 0.01 and rec.to_dict()["sigma_mm"] == 0.01
    ds = dataset_from_log(contents(recs))
    np.testing.assert_allclose(ds.temp_c, [20.0, 21.0, 22.0])
    np.testing.assert_allclose(ds.sigma_mm, [0.01, 0.02, 0.03])
    ds = dataset_from_log(contents([foreign_point(i, cov_mm2=COV) for i in range(2)]))
    np.testing.assert_allclose(ds.sigma_mm, np.sqrt(3e-4 * 3 / 3) * np.ones(2))    # sqrt(trace / 3)


def test_tracker_weather_with_a_gap_is_kept_but_a_top_level_temperature_gap_is_refused():
    weather = [foreign_point(i, **({} if i == 1 else {"temperatures": {"temp_c": 20.0 + i}})) for i in range(3)]
    ds = dataset_from_log(contents(weather))
    assert ds.temp_c is None and np.isnan(ds.env_temp_c[1]) and ds.env_temp_c[2] == 22.0
    top = [foreign_point(i, **({} if i == 1 else {"temp_c": 20.0})) for i in range(3)]
    with pytest.raises(DataError) as err:
        dataset_from_log(contents(top))
    assert str(err.value) == "log.jsonl: line 3: point record 2 (point_id 'P1'): has no 'temp_c' while other points do"


def _nest(i: int, **kw) -> dict:
    return {"point_id": f"N1@{i:03d}", "set": "nest", "kind": "nest", "nest_id": "N1",
            "p_tracker_mm": [5.0, 5.0, 5.0], "t_end_s": 90.0 + i, **kw}


@pytest.mark.parametrize("records, says", [
    ([foreign_point(0), foreign_point(1, set="warmup")],
     "line 3: point record 2 (point_id 'P1'): set must be calib, test, check or nest, got 'warmup'"),
    ([foreign_point(0), foreign_point(1, q_cmd_deg=[1.0, 2.0, 3.0])],
     "line 3: point record 2 (point_id 'P1'): 3 joint values, point record 1 has 2"),
    ([foreign_point(0, payload_kg=5.0), foreign_point(1)],
     "line 3: point record 2 (point_id 'P1'): has no 'payload_kg' while other points do"),
    ([_nest(1, t_end_s=None), foreign_point(0, t_end_s=None)],
     "line 2: point record 1 (point_id 'N1@001'): nest records need 't_end_s'"),
    ([_nest(1), foreign_point(0), _nest(2, nest_id="")],
     "line 4: point record 3 (point_id 'N1@002'): a nest record without 'nest_id'"),
], ids=["set", "joint_count", "optional_mix", "untimed_nests", "nest_id"])
def test_check_records_names_the_file_the_line_and_the_record(records, says):
    log = contents(records)
    with pytest.raises(DataError) as err:
        check_records(log.records(foreign=True), log.path, log.point_lines)
    assert str(err.value).startswith(f"log.jsonl: {says}") and "\n" not in str(err.value)
    with pytest.raises(DataError, match=says.replace("(", r"\(").replace(")", r"\)")):
        dataset_from_log(log)


def test_a_log_opening_with_nest_readings_only_passes_the_record_rules():
    """Reference nests read before the first robot point: the records are consistent (resume may continue);
    only the dataset needs a robot row."""
    log = contents([_nest(1), _nest(2, point_id="N2@001", nest_id="N2")])
    recs = log.records(foreign=True)
    assert all(isinstance(r, NestRecord) for r in recs)
    check_records(recs, log.path, log.point_lines)
    with pytest.raises(DataError, match="only nest records"):
        dataset_from_log(log)
