"""The typed log events: each writes exactly the bytes its raw dict wrote before events were typed, reads back to
an equal record, and a bad field is a RecordError naming it; the exit status is stored as its value."""
import pytest

from campaign.calibrate.adaptive_rounds import RoundCheck
from campaign.calibrate.adaptive_stop import RefitFailed, StopCheck
from campaign.io.json_fields import RecordError
from campaign.run.log_events import (EVENT_TYPES, DevicesEvent, EnvironmentFault, ExitStatus, FaultEvent,
                                     FirstPassEvent, ForecastEvent, JointTemperatureFault, NestReread, PauseEvent,
                                     ReacquireEvent, ResumeEvent, TrackerFault, TrackerStep, event_from_dict)
from campaign.run.log_reader import encode_record, read_log
from campaign.run.log_writer import RunLog

pytestmark = pytest.mark.unit
IDS = {"robot_identity": {"vendor": "ABB"}, "tracker_identity": {"vendor": "X"}, "driver_versions": {"software": "1"},
       "software_version": "1"}
# each record beside the raw dict the runner wrote for it before (keys in the order it wrote them)
CASES = [
    (PauseEvent("point P1: retries spent", 1.5), {"type": "pause", "reason": "point P1: retries spent", "t_s": 1.5}),
    (FaultEvent("robot", "motors off", 2), {"type": "fault", "device": "robot", "reason": "motors off", "t_s": 2}),
    (DevicesEvent(**IDS, speed_override_pct=None, t_s=0.0, motion_limits={"max_tcp_speed_mm_s": 250,
                                                                          "max_joint_speed_pct": 50.0}),
     {"type": "devices", **IDS, "motion_limits": {"max_tcp_speed_mm_s": 250, "max_joint_speed_pct": 50.0},
      "speed_override_pct": None, "t_s": 0.0}),
    (DevicesEvent(**IDS, speed_override_pct=75.0, t_s=0.0, payload={"mass_kg": 5, "cog_flange_mm": [0, 0, 50]}),
     {"type": "devices", **IDS, "payload": {"mass_kg": 5, "cog_flange_mm": [0, 0, 50]}, "speed_override_pct": 75.0,
      "t_s": 0.0}),
    (FirstPassEvent("start", 0.1, 100.0, 25), {"type": "first_pass", "state": "start", "max_tcp_speed_mm_s": 100.0,
                                               "max_joint_speed_pct": 25, "t_s": 0.1}),
    (FirstPassEvent("done", 9.0), {"type": "first_pass", "state": "done", "t_s": 9.0}),
    (EnvironmentFault("P2", "no weather", 3.0),
     {"type": "environment_fault", "point_id": "P2", "reason": "no weather", "t_s": 3.0}),
    (JointTemperatureFault("P2", "timeout", 3.0),
     {"type": "joint_temperature_fault", "point_id": "P2", "reason": "timeout", "t_s": 3.0}),
    (TrackerFault("P3", "beam_broken", 2, "beam broken", 4.0),
     {"type": "tracker_fault", "point_id": "P3", "kind": "beam_broken", "attempt": 2, "reason": "beam broken",
      "t_s": 4.0}),
    (ReacquireEvent("P3", "predicted", 4.5, [1000.0, 2.5, -3.125]),
     {"type": "reacquire", "point_id": "P3", "step": "predicted", "p_tracker_mm": [1000.0, 2.5, -3.125], "t_s": 4.5}),
    (ReacquireEvent("P3", "found", 5.0), {"type": "reacquire", "point_id": "P3", "step": "found", "t_s": 5.0}),
    (TrackerStep("P3", {"step": "find_reflector", "ok": True}, 5.0),
     {"type": "tracker_step", "point_id": "P3", "step": "find_reflector", "ok": True, "t_s": 5.0}),
    (ResumeEvent("paused", 17), {"type": "resume", "previous_exit": "paused", "dropped_tail_bytes": 17}),
    (ResumeEvent(None, 0), {"type": "resume", "previous_exit": None, "dropped_tail_bytes": 0}),
    (NestReread("nest N1 read 0.300 mm from its first reading", {"point_id": "N1@0", "set": "nest"}, 6.0),
     {"type": "nest_reread", "reason": "nest N1 read 0.300 mm from its first reading",
      "first_reading": {"point_id": "N1@0", "set": "nest"}, "t_s": 6.0}),
    (ForecastEvent([[25, 0.08], [50, 0.05]], 12.5, None),
     {"type": "forecast", "curve": [[25, 0.08], [50, 0.05]], "minutes_planned": 12.5, "minutes_grid": None}),
    (StopCheck(40, 0.05, None, 0.001, 0.03, 0.0, 0.05, 1.0, ((40, 0.05), (60, 0.045)), 3.0, "continue", "gain"),
     {"type": "stop_check", "n_calib": 40, "predicted_rms_mm": 0.05, "gain_next_mm": None, "threshold_mm": 0.001,
      "floor_mm": 0.03, "unmodelled_mm": 0.0, "cv_rms_mm": 0.05, "s0": 1.0, "curve": [[40, 0.05], [60, 0.045]],
      "elapsed_min": 3.0, "decision": "continue", "reason": "gain"}),
    (RefitFailed(40, "continue", "refit failed: singular"),
     {"type": "stop_check", "n_calib": 40, "decision": "continue", "reason": "refit failed: singular"}),
    (RoundCheck(30, "geometric", 0.06, 0.01, 0.001, 0.03, None, ((30, 0.06),), 2.0, "continue", "gain", ("A1",)),
     {"type": "adaptive_round", "n_calib": 30, "layer": "geometric", "predicted_rms_mm": 0.06, "gain_next_mm": 0.01,
      "threshold_mm": 0.001, "floor_mm": 0.03, "cv_rms_mm": None, "curve": [[30, 0.06]], "elapsed_min": 2.0,
      "decision": "continue", "reason": "gain", "added": ["A1"]}),
]


@pytest.mark.parametrize("record, legacy", CASES, ids=[f"{type(r).__name__}-{i}" for i, (r, _) in enumerate(CASES)])
def test_an_event_writes_the_bytes_of_its_raw_dict_and_reads_back_equal(record, legacy):
    assert encode_record("event", 7, record.to_dict()) == encode_record("event", 7, legacy)
    assert type(record).from_dict(legacy) == record
    assert type(record).from_dict(record.to_dict()).to_dict() == legacy


def test_every_run_event_type_is_read_by_its_record():
    seen = {type(r) for r, _ in CASES if type(r).TYPE in EVENT_TYPES}
    assert seen == set(EVENT_TYPES.values())
    for record, legacy in CASES:
        if type(record).TYPE in EVENT_TYPES:
            assert event_from_dict(legacy) == record


@pytest.mark.parametrize("data, field", [
    ({"type": "tracker_fault", "point_id": "P", "kind": "x", "attempt": "1", "reason": "r", "t_s": 1.0}, "attempt"),
    ({"type": "pause", "t_s": 1.0}, "reason"),
    ({"type": "devices", **IDS, "speed_override_pct": None, "t_s": True}, "t_s"),
    ({"type": "no_such_event"}, "type"),
])
def test_a_bad_event_names_its_field(data, field):
    with pytest.raises(RecordError) as err:
        event_from_dict(data)
    assert err.value.field == field


def test_the_stop_record_stores_the_exit_status_value(tmp_path):
    start = {"config_sha256": "ab", "plan_sha256": "cd", "config": {}, "created_utc": "t", "software_version": "1",
             "units": {}}
    log = RunLog.create(tmp_path, start)
    log.append_event(PauseEvent("why", 1.0))
    log.close(ExitStatus.PAUSED, "why")
    contents = read_log(tmp_path)
    assert contents.stops[-1]["exit_status"] == "paused" and contents.events == [PauseEvent("why", 1.0).to_dict()]
    assert ExitStatus("paused") is ExitStatus.PAUSED and f"{ExitStatus.ABORT}" == "abort"
