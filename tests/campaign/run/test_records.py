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


def _stats(rms: float | None, n: int) -> dict:
    return {"max_mm": None if rms is None else 2 * rms, "mean_mm": None if rms is None else 0.8 * rms, "rms_mm": rms,
            "n": n}


def _report_dict() -> dict:
    """A report.json of the current format with every optional section (GPR layer, elastic stage, three SMRs,
    plan.stop: auto, a registered tool), in the writer's key order."""
    layer = {"kind": "gpr", "calib_rms_mm": 0.01, "cv_predicted_rms_mm": 0.02, "folds": 5, "test_rms_mm": 0.021,
             "note": "calib_rms_mm is a fit", "approximation": "exact", "n_train": 40, "n_inducing": None,
             "noise_mm": 0.015, "noise_floor_mm": 0.012}
    spread = {"max_mm": 0.01, "mean_mm": 0.005, "rms_mm": 0.006, "n": 2, "per_point_mm": {"T1": 0.004, "T2": 0.01}}
    unident = {"name": "d1", "redundant_with": ["base_z"], "reason": "redundant"}
    return {
        "format": "campaign-report/1", "config": "c", "source": "s",
        "n": {"calib": 40, "test": 2, "check": 3, "rejected": 1},
        "stages": {"nominal": {"test": _stats(0.4, 2), "calib": _stats(0.41, 40)},
                   "kinematic": {"test": _stats(0.03, 2), "calib": _stats(0.025, 40)},
                   "elastic": {"test": _stats(0.025, 2), "calib": _stats(0.02, 40)},
                   "compensated": {"test": _stats(0.021, 2), "calib": _stats(0.01, 40), "test_pred_std_mm": spread,
                                   "layer": layer}},
        "noise_floor_mm": 0.02, "noise_floor_source": "repeats", "noise_floor_specs_mm": 0.03,
        "noise_floor_repeats_mm": 0.02,
        "parameters": [{"name": "a1", "unit": "mm", "delta": 0.3, "std": 0.01, "identified": True, "value": 150.3},
                       {"name": "d1", "unit": "mm", "delta": 0.0, "std": None, "identified": False, "value": 445.0}],
        "parameters_fit": "geometry + physical effects",
        "parameters_geometry_only": [{"name": "a1", "unit": "mm", "delta": 0.2, "std": 0.02, "identified": True,
                                      "value": 150.2},
                                     {"name": "d1", "unit": "mm", "delta": 0.0, "std": None, "identified": False,
                                      "value": 445.0}],
        "unidentifiable": [unident], "condition_number": 1.5e5, "observability": {"O1": 0.1, "O2": 1e-5},
        "sigma0": 0.9, "iterations": 6, "converged": True, "rejected_points": ["C7"],
        "excluded_points": [{"point_id": "C9", "set": "test", "reason": "SMR triangle"},
                            {"point_id": "C7", "set": "calib", "reason": "zero igg3 weight"}],
        "structure_note": None, "T_tracker_base": [[1.0, 0.0, 0.0, 10.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                                                   [0.0, 0.0, 0.0, 1.0]],
        "method": {"estimator": "robust_ridge", "weights": "igg3", "outliers": "local", "effects": "auto",
                   "residual": "gpr", "residual_config": "auto", "measurement_covariance": "spec"},
        "effects": {"selection": {"taken": ["joint_compliance(J2,3)"], "trials": [
                        {"effect": "joint_compliance(J2,3)", "candidate": "joint_compliance(J2,3)", "taken": True},
                        {"effect": "gear_cyclic(J1 h8)", "candidate": "gear_cyclic(J1 h5-40)", "taken": False},
                        {"effect": "gear_cyclic(J1 h9)", "candidate": "gear_cyclic(J1 h5-40)", "taken": False}]},
                    "fitted": [{"name": "joint_compliance", "options": {}, "params": {}}], "unidentifiable": [],
                    "sigma0": 0.95, "notes": [], "condition_number": 40.0, "counts": {"taken": 1, "tried": 2}},
        "residual_choice": {"chosen": "gpr", "folds": 5, "test": "paired t", "candidates": {
            "none": {"cv_rms_mm": 0.03}, "gpr": {"cv_rms_mm": 0.02, "gain": 0.33, "t": 4.0, "significant": True}}},
        "plausibility": {"unit": "mm", "scale": 1.0, "nominal_rms_mm": 0.41, "bound_mm": 23.0, "rejected_rows": [],
                         "notes": ["n"], "overridden": [], "forced": False, "max_length_delta_mm": 0.3,
                         "max_angle_delta_deg": 0.1,
                         "tool": {"configured_mm": [[0.0, 0.0, 39.4]], "registered_mm": [[0.0, 0.0, 39.4]],
                                  "difference_mm": [0.0], "directions_determined": 0, "note_above_mm": 3.0,
                                  "notes": []}},
        "residual_cv": {"folds": 5, "layer": "gpr", "rms_without_mm": 0.03, "rms_with_mm": 0.02, "gain": 0.33,
                        "t": 4.0, "significant": True},
        "preparation": {"joints": {"used": "readback"}, "drift": {"nests": 0}},
        "multi_smr": {"n_smr": 3, "p_flange_smr_mm": [[0.0, 0.0, 1.0]] * 3, "sigma0": 1.0, "converged": True,
                      "unidentifiable": [unident], "test": {"smr1": _stats(0.03, 2)},
                      "orientation_error_arcsec": {"mean": 20.0, "rms": 22.0, "max": 40.0, "n": 2}},
        "stop": {"rule": "r", "checks": [{"type": "stop_check", "curve": [[20, 0.05], [30, 0.04]]}],
                 "n_calib_at_stop": 30, "predicted_rms_mm": 0.04, "measured_rms_mm": 0.021, "reason": "gain"},
        "cell": {"robot_model": "IRB"}, "points": {"point_id": ["C1"]}}


def test_calibration_report_reads_and_writes_every_section_in_the_file_order():
    data = _report_dict()
    report = CalibrationReport.from_dict(data)
    assert json.dumps(report.to_dict()) == json.dumps(data)              # keys, order and values, nested too
    final = report.final
    assert report.n.test == 2 and final.layer.approximation == "exact" and final.test_pred_std_mm.n == 2
    assert report.excluded_points[0].set == "test" and report.unidentifiable[0].redundant_with == ("base_z",)
    assert report.multi_smr.orientation_error_arcsec.rms == 22.0 and report.stop.last_curve[-1] == [30, 0.04]
    assert report.plausibility.tool.registered_mm == ((0.0, 0.0, 39.4),) and report.residual_cv.predicts_structure
    no_gp = dict(data, stages={"compensated": {"test": _stats(None, 0), "calib": _stats(0.01, 3),
                                               "layer": {k: v for k, v in data["stages"]["compensated"]["layer"].items()
                                                         if k in ("kind", "calib_rms_mm", "cv_predicted_rms_mm",
                                                                  "folds", "test_rms_mm", "note")}}},
                 multi_smr={"n_smr": 2, "skipped": "the config names one SMR"})
    del no_gp["stop"]
    assert json.dumps(CalibrationReport.from_dict(no_gp).to_dict()) == json.dumps(no_gp)


def test_calibration_report_appends_identification_and_stays_unchanged():
    data = _report_dict()
    report = CalibrationReport.from_dict(data)
    ident = {"software_version": "1.0", "robot_identity": {"vendor": "ABB"}, "other": 1}
    out = report.with_identification(ident).to_dict()
    assert list(out)[-2:] == ["robot_identity", "software_version"] and "other" not in out
    assert "robot_identity" not in report.to_dict()              # the original is unchanged (frozen)


def test_calibration_report_of_an_earlier_version_reads_with_defaults():
    data = _report_dict()
    for section, key in (("method", "residual_config"), ("method", "measurement_covariance"),
                         ("residual_cv", "t"), ("residual_cv", "significant")):
        del data[section][key]
    del data["excluded_points"][0]["set"]
    for key in ("plausibility", "preparation", "multi_smr", "stop", "cell", "points", "effects"):
        del data[key]
    report = CalibrationReport.from_dict(data)
    assert report.method.residual_config is None and report.excluded_points[0].set == "calib"
    assert report.residual_cv.predicts_structure is True                    # gain 0.33 > 2 %: the earlier rule
    assert report.plausibility is None and report.stop is None and report.effects is None
    assert "residual_config" not in report.to_dict()["method"]


@pytest.mark.parametrize("path, value, field", [
    (("stages", "kinematic", "test", "rms_mm"), "0.1", "stages.kinematic.test.rms_mm"),
    (("n", "test"), -1, "n.test"),
    (("excluded_points", 1, "reason"), None, "excluded_points.1.reason"),
    (("multi_smr", "test", "smr1"), 3, "multi_smr.test.smr1"),
    (("plausibility", "tool", "directions_determined"), 1.5, "plausibility.tool.directions_determined"),
    (("stages",), None, "stages")])
def test_calibration_report_names_a_bad_nested_field_by_its_path(path, value, field):
    data = _report_dict()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(RecordError) as err:
        CalibrationReport.from_dict(data)
    assert err.value.field == field and repr(field) in str(err.value)


def _verify_dict() -> dict:
    held = {"stage": "model-corrected", "n_corrected": 2, "n_held": 1, "held": {"joint bound": 1},
            "all": _stats(0.03, 3), "corrected": _stats(0.02, 2),
            "orientation_error_arcsec": {"mean": 20.0, "rms": 21.0, "max": 30.0, "n": 3, "source": "estimated"}}
    return {"format": "campaign-verify/2", "run": "r", "n": 3, "noise_floor_mm": 0.02, "n_uncorrected": 1,
            "stages": {"uncorrected (planned joints)": _stats(0.4, 3), "model-corrected": _stats(0.03, 3)},
            "passes": [{"stage": "uncorrected (planned joints)", "n_corrected": 0, "n_held": 3, "held": {},
                        "all": _stats(0.4, 3), "corrected": None}, held],
            "exit_status": "success", "reason": "", "definitions": {"held": "h"},
            "created_utc": "2026-01-01T00:00:00+00:00"}


def test_verify_report_round_trip_and_errors():
    data = _verify_dict()
    report = VerifyReport.from_dict(data)
    assert json.dumps(report.to_dict()) == json.dumps(data)
    assert report.passes[1].orientation_error_arcsec.source == "estimated" and report.passes[0].corrected is None
    assert report.stages["model-corrected"].rms_mm == 0.03 and report.n == 3
    with pytest.raises(RecordError, match="'n'"):
        VerifyReport.from_dict({**data, "n": -1})
    with pytest.raises(RecordError, match="'passes': expected a list"):
        VerifyReport.from_dict({**data, "passes": 3})
    with pytest.raises(RecordError, match=r"'passes.1.all.rms_mm'"):
        VerifyReport.from_dict({**data, "passes": [data["passes"][0], {**data["passes"][1], "all": {"n": 3,
                                                                                                   "rms_mm": "x"}}]})
    first = {k: v for k, v in data.items() if k not in ("passes", "definitions")}      # campaign-verify/1
    old = VerifyReport.from_dict({**first, "format": "campaign-verify/1"})
    assert old.passes == () and old.definitions == {}
    with pytest.raises(RecordError, match="'passes': missing"):
        VerifyReport.from_dict(first)


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
