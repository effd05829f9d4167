"""Typed records (campaign/run/log_records.py): exact JSON of the log and reports, and field-naming errors."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from campaign.calibrate.calibration_report import CalibrationReport
from campaign.run.log_records import NestRecord, PointRecord, SmrReading, point_from_dict
from campaign.io.json_fields import RecordError
from campaign.correct.verify_report import VerifyReport
from campaign.run.log_writer import RunLog
from campaign.run.log_reader import RunLogError, read_log

pytestmark = pytest.mark.unit

COV = ((4e-4, 1e-5, 0.0), (1e-5, 5e-4, 2e-5), (0.0, 2e-5, 6e-4))
# the runner's key order before the records module existed (runner.measure_point's dict literal + its updates)
POINT_KEYS = ["point_id", "set", "q_cmd_deg", "q_read_deg", "p_tracker_mm", "cov_mm2", "cov_source", "spread_mm",
              "n_samples", "t_start_s", "t_measure_s", "t_end_s", "approach", "payload_kg", "retries",
              "p_target_base_mm"]
OPTIONAL_KEYS = ["temperatures", "joint_temp_c", "payload_cog_flange_mm", "device_std_mm", "device_cov_mm2",
                 "p2_tracker_mm", "cov2_mm2", "spread2_mm", "retries2", "p3_tracker_mm", "cov3_mm2", "spread3_mm",
                 "retries3"]


def point(**kw) -> PointRecord:
    base = PointRecord("P001", "calib", (10.0, -20.0, 30.0, 0.0, 45.0, 5.0), (10.001, -20.0, 30.0, 0.0, 45.0, 5.0),
                       (1500.0, -200.5, 800.25), COV, "spec", 0.004, 5, 1.0, 2.5, 4.0, (1.0, -1.0, 1.0, 1.0, 1.0, -1.0),
                       0.0, 0, (900.0, 100.0, 600.0))
    return replace(base, **kw)


def full_point() -> PointRecord:
    return point(temperatures={"temp_c": 20.5, "pressure_hpa": 1013.0}, joint_temp_c=(30.0,) * 6,
                 payload_kg=3.5, payload_cog_flange_mm=(0.0, 0.0, 50.0), device_std_mm=(0.01, 0.01, 0.02),
                 device_cov_mm2=COV, cov_source="device",
                 smrs=(SmrReading(2, (1.0, 2.0, 3.0), COV, 0.003, 1), SmrReading(3, (4.0, 5.0, 6.0), COV, 0.002, 0)))


def test_point_record_writes_the_runner_keys_in_order_and_omits_absent_options():
    assert list(point().to_dict()) == POINT_KEYS
    assert list(full_point().to_dict()) == POINT_KEYS + OPTIONAL_KEYS
    assert "temperatures" not in point(temperatures={}).to_dict()      # an empty weather read is left out


@pytest.mark.parametrize("rec", [point(), full_point()], ids=["minimal", "full"])
def test_point_record_round_trips_through_json(rec):
    data = json.loads(json.dumps(rec.to_dict()))
    back = point_from_dict(data)
    assert back == rec and back.to_dict() == data


@pytest.mark.parametrize("field, value, says", [
    ("p_tracker_mm", [1.0, 2.0], "3 finite numbers"),
    ("p_tracker_mm", None, "missing"),
    ("q_read_deg", [0.0] * 5, "6 finite numbers"),             # joint count must match q_cmd_deg
    ("cov_mm2", [[1, 0, 0], [0, 1, 0]], "3 x 3"),
    ("n_samples", True, "non-negative integer"),
    ("t_end_s", "soon", "finite number"),
    ("temperatures", [20.0], "object"),
    ("device_cov_mm2", None, "missing"),                        # required with device_std_mm
])
def test_point_record_from_dict_names_the_bad_field(field, value, says):
    data = full_point().to_dict()
    if value is None:
        del data[field]
    else:
        data[field] = value
    with pytest.raises(RecordError, match=says) as err:
        PointRecord.from_dict(data)
    assert err.value.field == field and repr(field) in str(err.value)


def test_fields_added_later_may_be_absent_and_stay_absent():
    data = point().to_dict()
    del data["t_measure_s"], data["cov_source"]
    rec = PointRecord.from_dict(data)
    assert rec.t_measure_s is None and rec.cov_source is None and rec.to_dict() == data


def test_nan_is_refused_by_name():
    data = point().to_dict()
    data["spread_mm"] = float("nan")
    with pytest.raises(RecordError) as err:
        PointRecord.from_dict(data)
    assert err.value.field == "spread_mm"


def test_nest_record_round_trip_and_type():
    rec = NestRecord("A@r1", "A", (1.0, 2.0, 3.0), COV, 0.001, 5, 1.0, 2.0, 0, (100.0, 0.0, 0.0),
                     {"temp_c": 21.0})
    data = json.loads(json.dumps(rec.to_dict()))
    assert data["set"] == data["kind"] == "nest" and data["t_s"] == 2.0
    assert point_from_dict(data) == rec
    del data["nest_id"]
    with pytest.raises(RecordError, match="nest_id"):
        point_from_dict(data)


def test_log_hands_back_typed_records_and_names_the_line_of_a_bad_one(tmp_path: Path):
    log = RunLog.create(tmp_path, {"config_sha256": "x"})
    log.append_point(full_point())
    log.append_point({**point(point_id="P002").to_dict(), "retries": -1})      # a foreign writer's bad record
    log.close()
    contents = read_log(tmp_path)
    assert contents.points[0] == full_point().to_dict() and contents.point_lines == [2, 3]
    with pytest.raises(RunLogError, match=r"line 3: point record 'P002': field 'retries'"):
        contents.records()


def _report_dict() -> dict:
    names = ["format", "config", "source", "n", "stages", "noise_floor_mm", "noise_floor_source",
             "noise_floor_specs_mm", "noise_floor_repeats_mm", "parameters", "unidentifiable", "condition_number",
             "observability", "sigma0", "iterations", "converged", "rejected_points", "excluded_points",
             "structure_note", "T_tracker_base", "method", "effects", "residual_choice", "plausibility",
             "residual_cv", "preparation", "multi_smr", "cell", "points"]
    out = {k: i for i, k in enumerate(names)}
    out.update(format="campaign-report/1", config="c", source="s", n={"calib": 3}, stages={}, method={},
               T_tracker_base=[[1.0]], multi_smr={"k": 1})
    return out


def test_calibration_report_keeps_the_key_order_and_appends_identification():
    data = _report_dict()
    report = CalibrationReport.from_dict(data)
    assert report.to_dict() == data and list(report.to_dict()) == list(data)
    assert report["stages"] == {} and report.get("missing") is None and report.n == {"calib": 3}
    ident = {"software_version": "1.0", "robot_identity": {"vendor": "ABB"}, "other": 1}
    out = report.with_identification(ident).to_dict()
    assert list(out)[-2:] == ["robot_identity", "software_version"] and "other" not in out
    assert "robot_identity" not in report                       # the original is unchanged (frozen)
    no_smr = dict(data)
    del no_smr["multi_smr"]
    assert list(CalibrationReport.from_dict(no_smr).to_dict()) == list(no_smr)
    del no_smr["stages"]
    with pytest.raises(RecordError, match="'stages'"):
        CalibrationReport.from_dict(no_smr)


def test_verify_report_round_trip_and_errors():
    data = {"format": "campaign-verify/2", "run": "r", "n": 3, "noise_floor_mm": 0.02, "n_uncorrected": None,
            "stages": {}, "passes": [], "exit_status": "success", "reason": "", "definitions": {},
            "created_utc": "2026-01-01T00:00:00+00:00"}
    report = VerifyReport.from_dict(data)
    assert report.to_dict() == data and list(report.to_dict()) == list(data) and report["n"] == 3
    with pytest.raises(RecordError, match="'n'"):
        VerifyReport.from_dict({**data, "n": -1})
    with pytest.raises(RecordError, match="'passes': expected a list"):
        VerifyReport.from_dict({**data, "passes": 3})


def test_report_page_refuses_a_verify_json_with_a_bad_field(tmp_path: Path):
    from campaign.errors import DataError
    from campaign.report.html import collect

    doc = {"format": "campaign-verify/2", "run": "r", "n": "three", "noise_floor_mm": 0.02, "n_uncorrected": None,
           "stages": {}, "passes": [], "exit_status": "success", "reason": "", "definitions": {},
           "created_utc": "2026-01-01T00:00:00+00:00"}
    (tmp_path / "verify-1").mkdir()
    (tmp_path / "verify-1" / "verify.json").write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"verify-1/verify.json: field 'n': expected a non-negative integer"):
        collect(tmp_path)
