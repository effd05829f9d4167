"""ABB RWS driver against the RWS emulator (RWS 1.0 and 2.0), the emulator against abb_robot_client, and the
emulator's protocol rules. Every test is bounded: driver timeouts are small and an alarm aborts any test that
runs longer than ``HARD_LIMIT_S``."""
from __future__ import annotations

import base64
import logging
import os
import signal
import subprocess
import sys
import time

import httpx
import pytest

from drivers import registry
from drivers.abb_rws import (AbbRwsRobot, OptionsError, RapidRejected, RwsOptions, calserver_source, fmt_jointtarget,
                             fmt_num, fmt_robtarget, fmt_string, load_credentials, parse_string)
from drivers.base import (ConnectionLost, DriverError, MotionError, MotionLimits, Payload, Robot, RobotError,
                          RobotNotReady)
from drivers.emulators.rws_server import (EmulatedMotionFault, RwsEmulator, parse_literal, parse_module, render)
from drivers.rws_client import RwsAuthError, RwsBusy

USER, PASSWORD = "Cal User", "Pw-7f3#kQz!93"
ENV = {"RWS_USER": USER, "RWS_PASSWORD": PASSWORD}
SECRETS = (PASSWORD, base64.b64encode(f"{USER}:{PASSWORD}".encode()).decode())
FAST = {"poll_s": 0.005, "settle_s": 0.01, "health_s": 0.03, "max_poll_rate_hz": 1000,
        "timeouts": {"connect_s": 2, "request_s": 2, "load_s": 2, "ack_s": 0.5, "move_s": 2},
        "retry": {"retries": 4, "backoff_s": 0.01, "backoff_max_s": 0.05, "heartbeat_s": 30}}
HARD_LIMIT_S = 10.0
pytestmark = pytest.mark.system


@pytest.fixture(autouse=True)
def deadline():
    """Abort a hung test after HARD_LIMIT_S (a never-hangs bound, not a timing check)."""
    def _alarm(signum, frame):
        raise TimeoutError(f"test exceeded {HARD_LIMIT_S} s")
    armed = hasattr(signal, "setitimer")
    if armed:
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, HARD_LIMIT_S)
    t0 = time.monotonic()
    yield
    if armed:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture(params=[1, 2], ids=["rws1", "rws2"])
def version(request) -> int:
    return request.param


@pytest.fixture
def make_emu():
    """Factory of started emulators (stopped at teardown)."""
    started = []

    def make(version: int = 1, **kw) -> RwsEmulator:
        kw.setdefault("joint_speed_deg_s", 3000.0)
        emu = RwsEmulator(version, user=USER, password=PASSWORD, **kw).start()
        started.append(emu)
        return emu
    yield make
    for emu in started:
        emu.stop()


@pytest.fixture
def emu(make_emu, version) -> RwsEmulator:
    return make_emu(version)


@pytest.fixture
def make_robot():
    """Factory of (unconnected) drivers with fast options; closed at teardown."""
    robots = []

    def make(emu: RwsEmulator, environ=ENV, **options) -> AbbRwsRobot:
        opts = {**FAST, **options}
        robot = registry.open_robot(emu.url, opts, environ=environ)
        robots.append(robot)
        return robot
    yield make
    for robot in robots:
        robot.close()


@pytest.fixture
def robot(emu, make_robot) -> AbbRwsRobot:
    r = make_robot(emu)
    r.connect()
    return r


def _stop_requests(emu: RwsEmulator) -> int:
    if emu.version == 1:
        return emu.count("POST", "/rw/rapid/execution", "action=stop")
    return emu.count("POST", "/rw/rapid/execution/stop")


def _no_secret(text: str) -> None:
    for secret in SECRETS:
        assert secret not in text


# --------------------------------------------------------------------------- codec and options


def test_rapid_literals():
    assert fmt_num(1.0) == "1" and fmt_num(-0.0000001) == "0" and fmt_num(12.3456789) == "12.345679"
    assert fmt_num(9e9) == "9E9"
    assert fmt_jointtarget([1, -2.5, 3, 4, 5, 6]) == "[[1,-2.5,3,4,5,6],[9E9,9E9,9E9,9E9,9E9,9E9]]"
    assert fmt_robtarget([1, 2, 3], [2, 0, 0, 0]) == "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
    assert parse_string(fmt_string('say "hi"')) == 'say "hi"'
    assert render(parse_literal("[[10.5,-20,15,0,45,90],[9E9,9E+09,9E9,9E9,9E9,9E9]]")) == \
        "[[10.5,-20,15,0,45,90],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]"


def test_shipped_module_declares_the_handshake():
    module = parse_module(calserver_source())
    types = {s.name: (s.storage, s.dtype) for s in module.symbols.values()}
    for name in ("cal_version", "cal_req_seq", "cal_ack_seq", "cal_done_seq", "cal_err_seq", "cal_err_no",
                 "cal_kind", "cal_settle_s"):
        assert types[name] == ("PERS", "num")
    assert types["cal_err_msg"] == ("PERS", "string")
    assert types["cal_target"] == types["cal_reached"] == ("PERS", "jointtarget")
    assert types["cal_ptarget"] == ("PERS", "robtarget") and types["cal_speed"] == ("PERS", "speeddata")
    assert types["cal_state"] == ("PERS", "num") and module.symbols["cal_state"].array
    assert types["cal_tool"] == ("PERS", "tooldata") and types["cal_vmax"] == types["cal_override"] == ("PERS", "num")
    assert module.name == "CalServer" and not module.has_main and module.routines["cal_run"] == ""
    source = calserver_source()
    assert "VelSet cal_override,cal_vmax;" in source and "IF cal_v.v_tcp>cal_vmax cal_v.v_tcp:=cal_vmax;" in source
    assert "MoveAbsJ cal_target,cal_v,fine,cal_tool" in source and "tool0\\WObj" not in source


def test_options_validation():
    assert RwsOptions.from_mapping({}).task == "T_ROB1"
    with pytest.raises(OptionsError, match=r"options: unknown key\(s\) upload_modul"):
        RwsOptions.from_mapping({"upload_modul": True})
    with pytest.raises(OptionsError, match=r"options.timeouts.move_s: expected a positive number"):
        RwsOptions.from_mapping({"timeouts": {"move_s": -1}})
    with pytest.raises(OptionsError, match=r"options.rws_version: expected auto, 1 or 2"):
        RwsOptions.from_mapping({"rws_version": 3})
    with pytest.raises(OptionsError, match=r"options.speed"):
        RwsOptions.from_mapping({"speed": [100, 50]})
    opts = RwsOptions.from_mapping({"rws_version": "2", "speed": (100, 50, 5000, 1000), "retry": {"retries": 2}})
    assert opts.rws_version == 2 and opts.speed == (100.0, 50.0, 5000.0, 1000.0) and opts.retry.retries == 2


def test_credentials_sources(tmp_path, caplog):
    opts = RwsOptions().credentials
    with pytest.raises(DriverError, match="set RWS_USER and RWS_PASSWORD"):
        load_credentials(opts, {})
    creds = load_credentials(RwsOptions.from_mapping({"credentials": {"use_default": True}}).credentials, {})
    assert creds.user == "Default User" and "robotics" not in repr(creds)
    names = RwsOptions.from_mapping({"credentials": {"user_env": "U", "password_env": "P"}}).credentials
    assert load_credentials(names, {"U": "a", "P": "b"}).password == "b"
    path = tmp_path / "rws.cred"
    path.write_text(f"# controller 1\nuser = {USER}\npassword = {PASSWORD}\n")
    path.chmod(0o644)
    with caplog.at_level(logging.WARNING):
        creds = load_credentials(RwsOptions.from_mapping({"credentials": {"file": str(path)}}).credentials, {})
    assert (creds.user, creds.password) == (USER, PASSWORD)
    assert "readable by other users" in caplog.text
    _no_secret(caplog.text + repr(creds) + str(creds))


# --------------------------------------------------------------------------- connect, move, read


def test_moves_and_joints(emu, robot):
    assert isinstance(robot, Robot) and robot.session.version == emu.version
    assert robot.session.client.base_url.scheme == emu.scheme
    targets = [(10, -20, 30, 40, 50, 60), (0, 5.25, -10.5, 0, 45.125, -90), (-30, 0, 0, 180, -60, 270)]
    for q in targets:
        robot.move_joints(q)
        assert robot.read_joints() == pytest.approx(q, abs=1e-4)
    assert [m[1] for m in emu.moves] == [tuple(map(float, q)) for q in targets]
    assert parse_literal(emu.symbol("cal_reached"))[0] == pytest.approx(targets[-1])
    assert parse_literal(emu.symbol("cal_speed")) == [200.0, 100.0, 200.0, 1000.0]
    assert emu.session_count == 1 and emu.counts["sessions"] == 1
    robot.close()
    robot.close()
    assert emu.counts["logouts"] == 1 and emu.session_count == 0


def test_move_linear(emu, robot):
    robot.move_linear((500, 100, 700), (0, 0, 2, 0), (0, -1, 0, 0))
    trans, quat, conf = emu.robtarget
    assert trans == [500, 100, 700] and quat == [0, 0, 1, 0] and conf == [0, -1, 0, 0]


def test_move_hook_is_the_simulated_robot(make_emu, make_robot):
    """The emulator's move_hook is where a simulated world plugs in: its answer becomes the actual joints."""
    seen = []

    def world(q):
        seen.append(q)
        return [v + 0.01 for v in q]
    emu = make_emu(1, move_hook=world)
    robot = make_robot(emu)
    robot.connect()
    robot.move_joints([1, 2, 3, 4, 5, 6])
    assert seen == [(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)]
    assert robot.read_joints() == pytest.approx([1.01, 2.01, 3.01, 4.01, 5.01, 6.01], abs=1e-5)


def test_invalid_target_is_refused_locally(robot):
    with pytest.raises(MotionError, match="expected 6 finite joint values"):
        robot.move_joints([0, 0, float("nan"), 0, 0, 0])


def test_forced_version_mismatch(make_emu, make_robot):
    emu = make_emu(1)
    robot = make_robot(emu, rws_version=2, scheme="http")
    with pytest.raises(DriverError, match="rws_version 2 was forced but the controller speaks RWS 1.0"):
        robot.connect()


def test_forced_version_and_scheme(make_emu, make_robot, version):
    """The forced RWS version and scheme are the ones used: one probe of ``/``, on the forced scheme, then every
    request in the forced flavour's grammar (1.0: ``json=1``; 2.0: without it, and never refused for its media
    type, 406); a forced scheme the controller does not serve is not replaced by the other one."""
    emu = make_emu(version)
    robot = make_robot(emu, rws_version=version, scheme=emu.scheme)
    robot.connect()
    robot.move_joints([5, 5, 5, 5, 5, 5])
    assert robot.session.version == version and robot.session.client.base_url.scheme == emu.scheme
    api = [(q, status) for _, path, q, status in emu.requests if path.startswith("/rw/")]
    assert emu.count("GET", "/") == 1 and api and all(status != 406 for _, status in api)
    assert all(("json=1" in q) == (version == 1) for q, _ in api)
    other = "http" if emu.scheme == "https" else "https"
    with pytest.raises(ConnectionLost, match="no RWS server found"):
        make_robot(emu, rws_version=version, scheme=other).connect()
    assert emu.count("GET", "/") == 1


# --------------------------------------------------------------------------- preflight


@pytest.mark.parametrize("setup, reason", [
    (lambda e: e.set_opmode("MANR"), "controller is in MANR mode, not AUTO"),
    (lambda e: e.set_ctrlstate("motoroff"), r"motors are not on \(ctrlstate=motoroff; press Motors On"),
    (lambda e: e.set_ctrlstate("guardstop"), r"motors are not on \(ctrlstate=guardstop; reset the stop"),
    (lambda e: e.hold_mastership("rapid"), r"mastership is held by another client \(RobotStudio\)"),
    (lambda e: e.hold_mastership("motion", "FlexPendant"), r"motion mastership is held by another client"),
    (lambda e: e.set_execution(False), "RAPID execution is stopped"),
], ids=["manual", "motors-off", "guardstop", "rapid-mastership", "motion-mastership", "rapid-stopped"])
def test_preflight_failures(emu, make_robot, setup, reason):
    setup(emu)
    robot = make_robot(emu)
    with pytest.raises(RobotNotReady, match=reason) as info:
        robot.connect()
    assert "\n" not in str(info.value)
    assert emu.counts["logouts"] == 1 and emu.session_count == 0


def test_preflight_module_missing(make_emu, make_robot, version):
    emu = make_emu(version, preload_calserver=False, rapid_running=False)
    with pytest.raises(RobotNotReady, match="RAPID module CalServer is not loaded in T_ROB1"):
        make_robot(emu).connect()


def test_preflight_calserver_not_answering(emu, make_robot):
    emu.calserver_alive = False                   # RAPID runs, but the loop never takes a request
    with pytest.raises(RobotNotReady, match=r"CalServer does not answer .*did not acknowledge within 0.5 s"):
        make_robot(emu).connect()
    assert _stop_requests(emu) == 1


def test_preflight_module_version(emu, make_robot):
    emu.set_symbol("cal_version", "1")
    with pytest.raises(RobotNotReady, match="CalServer interface version 1 on the controller, driver needs 2"):
        make_robot(emu).connect()


def test_reconnect_logs_previous_session_out(emu, robot):
    robot.connect()
    assert emu.counts["logouts"] == 1 and emu.session_count == 1
    robot.move_joints([1, 0, 0, 0, 0, 0])


def test_stale_cache_never_turns_a_move_into_a_ping(emu, robot):
    robot.move_joints([5, 5, 5, 5, 5, 5])
    emu.set_symbol("cal_kind", "0")               # e.g. the operator reloaded the module (PERS reinitialised)
    robot.move_joints([6, 6, 6, 6, 6, 6])
    assert robot.read_joints() == pytest.approx([6] * 6)


def test_preflight_can_switch_motors_on_and_start(emu, make_robot):
    emu.set_ctrlstate("motoroff")
    robot = make_robot(emu, motors_on=True, start_rapid=True)
    robot.connect()
    assert emu.ctrlstate == "motoron" and emu.execution == "running"
    robot.move_joints([1, 1, 1, 1, 1, 1])


def test_upload_module_installs_calserver(make_emu, make_robot, version):
    emu = make_emu(version, preload_calserver=False, rapid_running=False)
    robot = make_robot(emu, upload_module=True)
    robot.connect()
    assert emu.files["HOME/CalServer.mod"] == calserver_source().encode("latin-1")
    assert "calserver" in emu.modules and emu.execution == "running" and emu.pp == ("CalServer", "cal_run")
    assert not emu.mastership                      # released before start
    robot.move_joints([3, 2, 1, 0, 10, 20])
    assert robot.read_joints() == pytest.approx([3, 2, 1, 0, 10, 20])


def test_upload_module_replaces_running_calserver(emu, make_robot):
    robot = make_robot(emu, upload_module=True)
    robot.connect()
    robot.move_joints([1, 2, 3, 4, 5, 6])
    assert emu.count("POST", "/rw/rapid/execution", "action=stop") + \
        emu.count("POST", "/rw/rapid/execution/stop") == 1


# --------------------------------------------------------------------------- session faults


def test_503_storm_backs_off_and_recovers(emu, robot, caplog):
    with caplog.at_level(logging.WARNING, logger="drivers"):
        emu.inject_503(3)
        robot.move_joints([7, 7, 7, 7, 7, 7])
    assert sum(1 for *_, status in emu.requests if status == 503) == 3
    assert caplog.text.count("answered 503") == 3
    assert robot.read_joints() == pytest.approx([7] * 6)
    assert emu.counts["sessions"] == 1              # the same session (cookies kept)


def test_503_persisting_is_a_clean_error(emu, robot):
    emu.inject_503(1000)
    t0 = time.monotonic()
    with pytest.raises(RwsBusy, match=r"HTTP 503 after 5 attempts") as info:
        robot.read_joints()
    assert isinstance(info.value, ConnectionLost) and time.monotonic() - t0 < 5.0
    emu.inject_503(0)
    assert robot.read_joints() == pytest.approx([0, 0, 0, 0, 30, 0])
    emu.inject_503(1000)                             # lost in the middle of writing a request...
    with pytest.raises(RwsBusy):
        robot.move_joints([8, 8, 8, 8, 8, 8])
    emu.inject_503(0)
    robot.move_joints([9, 9, 9, 9, 9, 9])            # ...the next move checks and resynchronises first
    assert robot.read_joints() == pytest.approx([9] * 6)


def test_401_mid_run_reauthenticates(emu, robot, caplog):
    robot.move_joints([1, 1, 1, 1, 1, 1])
    with caplog.at_level(logging.WARNING, logger="drivers"):
        emu.inject_401(2 if emu.version == 1 else 1)   # Digest: httpx itself retries once before the driver
        robot.move_joints([2, 2, 2, 2, 2, 2])
    assert "re-authenticating" in caplog.text
    assert emu.counts["sessions"] == 2 and emu.session_count == 1
    emu.expire_sessions()                           # silent expiry: stale nonce / new Basic session
    robot.move_joints([3, 3, 3, 3, 3, 3])
    assert robot.read_joints() == pytest.approx([3] * 6) and emu.counts["sessions"] == 3


def test_wrong_password_is_refused_without_leaking(emu, make_robot, caplog):
    robot = make_robot(emu, environ={"RWS_USER": USER, "RWS_PASSWORD": PASSWORD + "x"})
    with caplog.at_level(logging.DEBUG):
        with pytest.raises(RwsAuthError, match="credentials rejected") as info:
            robot.connect()
    _no_secret(str(info.value) + repr(info.value) + caplog.text)
    assert (PASSWORD + "x") not in caplog.text + str(info.value)


def test_heartbeat_when_idle(emu, make_robot):
    robot = make_robot(emu, retry={**FAST["retry"], "heartbeat_s": 0.05})
    robot.connect()
    path = "/rw/panel/ctrlstate" if emu.version == 1 else "/rw/panel/ctrl-state"
    before = emu.count("GET", path)
    time.sleep(0.08)
    robot.read_joints()
    assert emu.count("GET", path) == before + 1
    robot.heartbeat()
    assert emu.count("GET", path) == before + 2


def test_session_cap_answers_503(make_emu, make_robot):
    emu = make_emu(2, max_sessions=1)
    robot = make_robot(emu, retry={"retries": 1, "backoff_s": 0.01})
    robot.connect()
    other = httpx.Client(base_url=emu.base_url, verify=False, auth=httpx.BasicAuth(USER, PASSWORD),
                         headers={"Accept": "application/hal+json;v=2.0"})
    with other:
        assert other.get("/rw/panel/opmode").status_code == 503
        robot.close()
        assert other.get("/rw/panel/opmode").status_code == 200


# --------------------------------------------------------------------------- motion faults


def test_motors_off_mid_move(emu, robot):
    robot.move_joints([1, 1, 1, 1, 1, 1])
    emu.fail_next_move("motors_off")
    with pytest.raises(MotionError, match=r"motors went off \(ctrlstate=guardstop\); elog: 20205 Auto stop open"):
        robot.move_joints([20, 20, 20, 20, 20, 20])
    assert _stop_requests(emu) == 1
    with pytest.raises(RobotNotReady, match=r"ctrlstate=guardstop, RAPID stopped"):
        robot.move_joints([2, 2, 2, 2, 2, 2])


def test_motors_off_by_operator_during_slow_move(make_emu, make_robot, version):
    emu = make_emu(version, joint_speed_deg_s=50.0)
    robot = make_robot(emu)
    robot.connect()
    timer = __import__("threading").Timer(0.1, emu.set_ctrlstate, ("motoroff",))
    timer.start()
    with pytest.raises(MotionError, match=r"motors went off \(ctrlstate=motoroff\)"):
        robot.move_joints([40, 0, 0, 0, 30, 0])
    timer.join()
    assert 0 < emu.joints[0] < 40 and _stop_requests(emu) == 1


def test_rapid_stopped_mid_move(emu, robot):
    emu.fail_next_move("rapid_stop", code=50050, message="Position outside reach")
    with pytest.raises(MotionError, match=r"RAPID execution stopped; elog: 50050 Position outside reach"):
        robot.move_joints([10, 10, 10, 10, 10, 10])
    emu.set_execution(True)                          # operator restarts; the driver resynchronises
    robot.move_joints([11, 11, 11, 11, 11, 11])
    assert robot.read_joints() == pytest.approx([11] * 6)


def test_joint_limit_stops_rapid(emu, robot):
    with pytest.raises(MotionError, match=r"RAPID execution stopped; elog: 50027 Joint Out of Range"):
        robot.move_joints([0, 170, 0, 0, 0, 0])


def test_hook_fault_stops_rapid(make_emu, make_robot):
    def collide(q):
        raise EmulatedMotionFault("Motion supervision", code=50204)
    emu = make_emu(2, move_hook=collide)
    robot = make_robot(emu)
    robot.connect()
    with pytest.raises(MotionError, match="50204 Motion supervision"):
        robot.move_joints([5, 5, 5, 5, 5, 5])


def test_error_sequence_from_rapid(emu, robot):
    emu.fail_next_move("error", message="CalServer: move rejected, ERRNO 41617", code=41617)
    with pytest.raises(RapidRejected, match=r"rejected by RAPID: CalServer: move rejected, ERRNO 41617 "
                                            r"\(ERRNO 41617\)") as info:
        robot.move_joints([10, 10, 10, 10, 10, 10])
    assert info.value.errno == 41617 and isinstance(info.value, MotionError)
    assert _stop_requests(emu) == 0                  # RAPID still serves: the next request works
    robot.move_joints([12, 12, 12, 12, 12, 12])
    assert robot.read_joints() == pytest.approx([12] * 6)


def test_move_that_never_finishes_times_out(emu, make_robot):
    robot = make_robot(emu, timeouts={**FAST["timeouts"], "move_s": 0.2})
    robot.connect()
    emu.fail_next_move("hang")
    t0 = time.monotonic()
    with pytest.raises(MotionError, match=r"not done within 0.71 s"):
        robot.move_joints([10, 10, 10, 10, 10, 10])
    assert time.monotonic() - t0 < 5.0 and _stop_requests(emu) == 1


def test_stop_is_best_effort(emu, robot):
    robot.stop()
    assert emu.execution == "stopped"
    emu.stop()                                       # server gone: stop() must still not raise
    robot.stop()


def test_password_never_in_errors_or_logs(emu, make_robot, caplog):
    caplog.set_level(logging.DEBUG)
    texts = []
    emu.set_opmode("MANR")
    with pytest.raises(RobotNotReady) as info:
        make_robot(emu).connect()
    texts.append(repr(info.value))
    emu.set_opmode("AUTO")                          # leaving AUTO stopped RAPID: the operator restarts it
    emu.set_execution(True)
    robot = make_robot(emu)
    robot.connect()
    for fault in ("motors_off", "rapid_stop", "error"):
        emu.set_ctrlstate("motoron")
        emu.set_execution(True)
        emu.fail_next_move(fault)
        with pytest.raises(RobotError) as info:
            robot.move_joints([4, 4, 4, 4, 4, 4])
        texts.append(repr(info.value) + str(info.value))
    emu.inject_503(100)
    with pytest.raises(RwsBusy) as info:
        robot.read_joints()
    texts.append(str(info.value))
    texts += [repr(robot.session._credentials), repr(robot.opts)]
    texts += [r.getMessage() + str(r.args) for r in caplog.records]
    for text in texts:
        _no_secret(text)


# --------------------------------------------------------------------------- write-back


def test_write_module_round_trip(emu, robot):
    text = ("MODULE CalCorr\n    ! corrected targets\n"
            "    CONST jointtarget jc1:=[[10.5,-20,15,0,45,90],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
            "    PERS num corr_count:=1;\nENDMODULE\n")
    robot.write_module("CalCorr", text)
    assert emu.files["HOME/CalCorr.mod"] == text.encode("latin-1")
    assert emu.symbol("jc1", "CalCorr") == "[[10.5,-20,15,0,45,90],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]"
    assert emu.execution == "running" and not emu.mastership
    robot.move_joints([1, 2, 3, 4, 5, 6])           # CalServer still serves after the reload
    robot.write_module("CalCorr", text.replace("corr_count:=1", "corr_count:=2"))
    assert emu.symbol("corr_count", "CalCorr") == "2"


def test_write_module_detects_corrupted_read_back(emu, robot):
    real_get = emu._get_file

    def corrupting(req, s, raw):
        resp = real_get(req, s, raw)
        resp.body = resp.body.replace(b"10.5", b"10.6")
        return resp
    emu._get_file = corrupting
    text = "MODULE CalCorr\n    CONST num k:=10.5;\nENDMODULE\n"
    with pytest.raises(RobotError, match="read-back of \\$HOME/CalCorr.mod differs"):
        robot.write_module("CalCorr", text)
    assert "calcorr" not in emu.modules


def test_write_module_validates_text(robot):
    with pytest.raises(RobotError, match="must start with 'MODULE CalCorr'"):
        robot.write_module("CalCorr", "MODULE Other\nENDMODULE\n")
    with pytest.raises(RobotError, match="not a RAPID module name"):
        robot.write_module("1bad", "MODULE 1bad\nENDMODULE\n")


def test_write_module_refused_by_syntax_error(emu, robot):
    with pytest.raises(RobotError, match="-1073442814"):
        robot.write_module("CalCorr", "MODULE CalCorr\n  CONST jointtarget j:=[[1,2]];\nENDMODULE\n")
    assert emu.execution == "running" and not emu.mastership     # left as found
    robot.move_joints([1, 1, 1, 1, 1, 1])


# --------------------------------------------------------------------------- emulator protocol rules


def _client(emu: RwsEmulator, password: str = PASSWORD) -> httpx.Client:
    if emu.version == 1:
        return httpx.Client(base_url=emu.base_url, auth=httpx.DigestAuth(USER, password), params={"json": "1"})
    return httpx.Client(base_url=emu.base_url, verify=False, auth=httpx.BasicAuth(USER, password),
                        headers={"Accept": "application/hal+json;v=2.0",
                                 "Content-Type": "application/x-www-form-urlencoded;v=2.0"})


def _code(resp: httpx.Response) -> int:
    doc = resp.json()
    return int((doc.get("status") or doc["_embedded"]["status"])["code"])


def test_emulator_authentication(emu):
    with httpx.Client(base_url=emu.base_url, verify=False) as anon:
        challenge = anon.get("/").headers["www-authenticate"]
    if emu.version == 1:
        assert challenge.startswith('Digest realm="validusers@robapi.abb"') and 'qop="auth"' in challenge
    else:
        assert challenge == 'Basic realm="validusers@robapi.abb"'
    with _client(emu, "wrong") as bad:
        assert bad.get("/rw/panel/opmode").status_code == 401
    with _client(emu) as good:
        resp = good.get("/rw/panel/opmode")
        assert resp.status_code == 200 and {"-http-session-", "ABBCX"} <= set(good.cookies.keys())
        good.auth = None                              # the cookie alone authenticates
        assert good.get("/rw/panel/opmode").status_code == 200
        assert good.get("/logout").status_code == 204
        assert good.get("/rw/panel/opmode").status_code == 401


def test_emulator_rws2_media_types(make_emu):
    emu = make_emu(2)
    with _client(emu) as c:
        assert c.get("/rw/panel/opmode", headers={"Accept": "application/json"}).status_code == 406
        path = "/rw/rapid/symbol/RAPID/T_ROB1/CalServer/cal_settle_s/data"
        assert c.post(path, params={"mastership": "implicit"}, content=b"value=1",
                      headers={"Content-Type": "application/x-www-form-urlencoded"}).status_code == 415
        plain = c.put("/fileservice/$HOME/a.txt", content=b"x", headers={"Content-Type": "text/plain"})
        assert plain.status_code == 415
        assert c.put("/fileservice/%24HOME/a.txt", content=b"x",
                     headers={"Content-Type": "text/plain;v=2.0"}).status_code == 201
        assert c.get("/fileservice/HOME/a.txt").content == b"x"


def test_emulator_rapid_rules(emu):
    v1 = emu.version == 1
    sym = ("/rw/rapid/symbol/data/RAPID/T_ROB1/CalServer/{}" if v1
           else "/rw/rapid/symbol/RAPID/T_ROB1/CalServer/{}/data")
    write = {"action": "set"} if v1 else {"mastership": "implicit"}
    ctrl = "/rw/rapid/execution"
    with _client(emu) as c:
        missing = c.get(sym.format("nope"))
        assert (missing.status_code, _code(missing)) == ((400, -1073414146) if v1 else (404, -1073442816))
        bad = c.post(sym.format("cal_target"), params=write, data={"value": "[[1,2],[3]]"})
        assert (bad.status_code, _code(bad)) == (400, -1073445879)
        if not v1:
            explicit = c.post(sym.format("cal_settle_s"), data={"value": "1"})
            assert (explicit.status_code, _code(explicit)) == (403, -1073445859)
        load = c.post("/rw/rapid/tasks/T_ROB1" if v1 else "/rw/rapid/tasks/T_ROB1/loadmod",
                      params={"action": "loadmod"} if v1 else {"mastership": "implicit"},
                      data={"modulepath": "$HOME/none.mod", "replace": "true"})
        assert _code(load) == -1073442809            # RAPID running
        emu.hold_mastership("rapid")
        held = c.post(sym.format("cal_settle_s"), params=write, data={"value": "1"})
        assert (held.status_code, _code(held)) == (403, -1073445862)
        emu.release_foreign_mastership("rapid")
        assert c.post(ctrl if v1 else ctrl + "/stop", params={"action": "stop"} if v1 else {},
                      data={"stopmode": "stop"}).status_code == 204
        if v1:                                        # RWS 1.0 loadmod has no implicit mastership
            denied = c.post("/rw/rapid/tasks/T_ROB1", params={"action": "loadmod"},
                            data={"modulepath": "$HOME/none.mod", "replace": "true"})
            assert (denied.status_code, _code(denied)) == (403, -1073445859)
            assert c.post("/rw/mastership/rapid", params={"action": "request"}).status_code == 204
        load = c.post("/rw/rapid/tasks/T_ROB1" if v1 else "/rw/rapid/tasks/T_ROB1/loadmod",
                      params={"action": "loadmod"} if v1 else {"mastership": "implicit"},
                      data={"modulepath": "$HOME/none.mod", "replace": "true"})
        assert (load.status_code, _code(load)) == (400, -1073438708)
        emu.set_ctrlstate("motoroff")
        start = {"regain": "continue", "execmode": "continue", "cycle": "forever", "condition": "none",
                 "stopatbp": "disabled", "alltaskbytsp": "false"}
        refused = c.post(ctrl if v1 else ctrl + "/start", params={"action": "start"} if v1 else {}, data=start)
        assert (refused.status_code, _code(refused)) == (400, -1073442809)


def test_emulator_rws2_start_refused_while_holding_edit(make_emu):
    emu = make_emu(2, rapid_running=False)
    with _client(emu) as c:
        assert c.post("/rw/mastership/edit/request").status_code == 204
        resp = c.post("/rw/rapid/execution/start", data={"regain": "continue", "execmode": "continue",
                                                         "cycle": "forever", "condition": "none",
                                                         "stopatbp": "disabled", "alltaskbytsp": "false"})
        assert (resp.status_code, _code(resp)) == (403, -1073445862)
        assert c.post("/rw/mastership/edit/release").status_code == 204
        assert c.post("/rw/rapid/execution/start", data={"cycle": "forever"}).status_code == 204


def test_emulator_cli_prints_port():
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "drivers.emulators.rws_server", "--version", "1", "--port", "0",
                             "--print-port"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    try:
        port = int(proc.stdout.readline())
        resp = httpx.get(f"http://127.0.0.1:{port}/", timeout=2)
        assert resp.status_code == 401 and resp.headers["www-authenticate"].startswith("Digest")
    finally:
        proc.terminate()
        proc.communicate(timeout=3)


def test_emulator_refuses_non_loopback():
    with pytest.raises(ValueError, match="loopback only"):
        RwsEmulator(1, host="0.0.0.0")


# --------------------------------------------------------------------------- third-party client


def test_abb_robot_client_rws1(make_emu):
    """abb_robot_client 0.4 (requests + Digest) reads and writes through the emulator."""
    rws = pytest.importorskip("abb_robot_client.rws")
    emu = make_emu(1)
    client = rws.RWS(emu.base_url, USER, PASSWORD)
    assert client.get_controller_state() == "motoron"
    assert client.get_operation_mode() == "AUTO"
    assert tuple(client.get_execution_state()) == ("running", "forever")
    joints = client.get_jointtarget("ROB_1")
    assert list(joints.robax) == [0, 0, 0, 0, 30, 0] and list(joints.extax) == [9e9] * 6
    assert client.get_robtarget().rot.tolist() == [0, 0, 1, 0]
    assert client.get_rapid_variable("cal_req_seq") == "0"
    assert client.get_rapid_variable("CalServer/cal_settle_s") == "0.5"
    client.set_rapid_variable("cal_settle_s", "0.25")
    assert client.get_rapid_variable("cal_settle_s") == "0.25" == emu.symbol("cal_settle_s")
    client.set_rapid_variable("cal_err_msg", '"Hello World!"')
    assert client.get_rapid_variable("cal_err_msg") == '"Hello World!"'
    client.set_rapid_variable_num("cal_kind", 2)
    assert client.get_rapid_variable_num("cal_kind") == 2.0
    with pytest.raises(rws.ABBException) as info:
        client.set_rapid_variable("cal_kind", '"text"')
    assert info.value.code == -1073445879
    assert client.get_tasks()["T_ROB1"].motiontask
    entries = client.read_event_log()
    assert entries[0].code == 10151 and entries[0].seqnum > entries[1].seqnum
    client.upload_file("$HOME/hello.txt", b"hello")
    assert client.read_file("$HOME/hello.txt") == b"hello" and "hello.txt" in client.list_files("$HOME")
    assert client.get_speedratio() == 100.0
    client.stop()
    client.resetpp()
    client.start(cycle="forever")
    assert client.get_execution_state().ctrlexecstate == "running"
    client.logout()
    assert emu.counts["logouts"] == 1 and emu.counts["sessions"] == 1


def wait_done(client, seq: str, timeout_s: float = 30.0) -> None:
    """Poll CalServer/cal_done_seq through a third-party client until it reads ``seq`` (fails after ``timeout_s``:
    a loaded machine slows the emulated move, never skips it)."""
    deadline = time.monotonic() + timeout_s
    while client.get_rapid_variable("CalServer/cal_done_seq") != seq:
        assert time.monotonic() < deadline, f"CalServer did not report request {seq} done within {timeout_s} s"
        time.sleep(0.01)


def test_abb_robot_client_drives_calserver_handshake(make_emu):
    """The emulated CalServer loop answers the handshake written by an independent client."""
    rws = pytest.importorskip("abb_robot_client.rws")
    emu = make_emu(1)
    client = rws.RWS(emu.base_url, USER, PASSWORD)
    client.set_rapid_variable("CalServer/cal_target", fmt_jointtarget([15, 25, 35, 45, 55, 65]))
    client.set_rapid_variable("CalServer/cal_settle_s", "0")
    client.set_rapid_variable("CalServer/cal_kind", "1")
    client.set_rapid_variable("CalServer/cal_req_seq", "1")
    wait_done(client, "1")
    assert client.get_rapid_variable("CalServer/cal_ack_seq") == "1"
    assert client.get_jointtarget().robax.tolist() == [15, 25, 35, 45, 55, 65]
    client.logout()


@pytest.mark.parametrize("implicit", [True, False], ids=["implicit", "explicit"])
def test_rw7_client_reads_state_and_writes_pers(make_emu, implicit):
    """A public RW7 client: the RWS 2.0 class ``RWS2`` of the Mesh-ch fork of abb_robot_client (GitHub
    Mesh-ch/abb_robot_client, 0.5.3; requests + Basic over HTTPS). Not on PyPI, so it is skipped unless installed
    (``pip install git+https://github.com/Mesh-ch/abb_robot_client``); see docs/drivers_abb.md."""
    rws2 = pytest.importorskip("abb_robot_client.rws2")
    emu = make_emu(2, implicit_mastership=implicit)
    client = rws2.RWS2(emu.base_url, USER, PASSWORD)
    assert emu.tls and client.get_controller_state() == "motoron" and client.get_operation_mode() == "AUTO"
    assert client.get_execution_state().ctrlexecstate == "running"
    assert client.get_jointtarget("T_ROB1").robax.tolist() == [0, 0, 0, 0, 30, 0]  # /rw/rapid/tasks/T_ROB1/motion/...
    assert client.get_robtarget().rot.tolist() == [0, 0, 1, 0]
    assert client.get_speedratio() == 100
    client.set_rapid_variable("CalServer/cal_settle_s", "0.75")                      # a PERS write
    assert client.get_rapid_variable("CalServer/cal_settle_s") == "0.75" == emu.symbol("cal_settle_s")
    client.set_rapid_variable("CalServer/cal_target", fmt_jointtarget([15, 25, 35, 45, 55, 65]))
    client.set_rapid_variable("CalServer/cal_settle_s", "0")
    client.set_rapid_variable("CalServer/cal_kind", "1")
    client.set_rapid_variable("CalServer/cal_req_seq", "1")                          # the CalServer handshake
    wait_done(client, "1")
    assert client.get_jointtarget().robax.tolist() == [15, 25, 35, 45, 55, 65]
    assert client.get_mechunits() == ["ROB_1"] and "T_ROB1" in client.get_tasks()
    assert client.read_event_log()[0].seqnum == emu.elog[-1]["seqnum"]
    client.stop()
    if implicit:                                                                     # resetpp?mastership=implicit
        client.resetpp()
        assert emu.pp == ("MainModule", "main")
    client.start()
    assert client.get_execution_state().ctrlexecstate == "running"
    assert not emu.mastership                                                        # the client released it


# --------------------------------------------------------------------------- issue 13: routine entry, mastership, caps


def _pp_requests(emu: RwsEmulator) -> int:
    if emu.version == 1:
        return emu.count("POST", "/rw/rapid/tasks/T_ROB1/pcp", "action=set-pp-routine")
    return emu.count("POST", "/rw/rapid/tasks/T_ROB1/pcp/routine")


def test_calserver_runs_as_a_routine_next_to_the_production_main(make_emu, make_robot, version):
    """The production program (its own main, not calling CalServer) stays loaded; the driver sets the PP to
    cal_run, and at close stops RAPID and puts the PP back to main."""
    emu = make_emu(version, customer_program="plain", rapid_running=False)
    assert emu.pp == ("MainModule", "main") and emu.link_error() == ""
    robot = make_robot(emu, start_rapid=True)
    robot.connect()
    assert emu.pp == ("CalServer", "cal_run") and emu.execution == "running" and _pp_requests(emu) == 1
    robot.move_joints([4, 3, 2, 1, 20, 10])
    assert {"mainmodule", "calserver"} <= set(emu.modules)
    robot.close()
    assert emu.pp == ("MainModule", "main") and emu.execution == "stopped" and not emu.mastership


def test_upload_next_to_production_main_uses_the_routine(make_emu, make_robot, version):
    emu = make_emu(version, preload_calserver=False, customer_program="plain", rapid_running=False)
    robot = make_robot(emu, upload_module=True)
    robot.connect()
    assert emu.pp == ("CalServer", "cal_run") and emu.link_error() == ""
    robot.move_joints([1, 2, 3, 4, 5, 6])
    robot.close()
    assert emu.pp == ("MainModule", "main")


def test_entry_main_when_the_production_main_calls_cal_run(make_emu, make_robot, version):
    emu = make_emu(version, customer_program="calls", rapid_running=False)
    robot = make_robot(emu, start_rapid=True, entry="main")
    robot.connect()
    assert emu.pp == ("MainModule", "main") and _pp_requests(emu) == 0
    robot.move_joints([2, 2, 2, 2, 2, 2])
    robot.close()
    assert emu.execution == "running"                  # the operator's program: left as it was


def test_emulator_refuses_a_second_main_like_a_controller(make_emu, make_robot, tmp_path, version):
    """A module with its own PROC main next to the production main loads, but the program does not link:
    the event log says so and start / PP moves are refused with E_RAPID_SEMANTIC_ERROR."""
    emu = make_emu(version, preload_calserver=False, customer_program="plain", rapid_running=False)
    legacy = calserver_source().replace("PROC cal_run()", "PROC main()")
    module_file = tmp_path / "CalServer.mod"
    module_file.write_text(legacy, encoding="latin-1")
    robot = make_robot(emu, upload_module=True, module_file=str(module_file))
    with pytest.raises(RobotNotReady, match="-1073442802 E_RAPID_SEMANTIC_ERROR.*Ambiguous name main"):
        robot.connect()
    assert "Ambiguous name main" in emu.link_error() and emu.elog[-1]["title"] == "Link error"
    assert emu.execution == "stopped"


def test_explicit_mastership_when_implicit_is_refused(make_emu, make_robot, caplog):
    emu = make_emu(2, implicit_mastership=False)
    robot = make_robot(emu)
    with caplog.at_level(logging.WARNING):
        robot.connect()
        robot.move_joints([7, 6, 5, 4, 3, 2])
    assert robot.read_joints() == pytest.approx([7, 6, 5, 4, 3, 2])
    assert "E_MASTER_REJECT" in caplog.text and emu.count("POST", "/rw/mastership/edit/request") >= 2
    assert not emu.mastership                              # released after every block of writes


def test_explicit_mastership_retries_while_another_client_edits(make_emu, make_robot):
    emu = make_emu(2, implicit_mastership=False)
    robot = make_robot(emu)
    robot.connect()
    emu.hold_mastership("edit", "FlexPendant", release_after=2)   # a short edit elsewhere
    robot.move_joints([1, 1, 1, 1, 1, 1])
    assert robot.read_joints() == pytest.approx([1] * 6)
    emu.hold_mastership("edit", "RobotStudio")                       # held for good: a clean refusal
    with pytest.raises(RobotNotReady, match="edit mastership is held by another client"):
        robot.move_joints([2, 2, 2, 2, 2, 2])


def test_internal_mastership_is_not_foreign(emu, make_robot):
    client = httpx.Client(base_url=emu.base_url, verify=False, auth=httpx.DigestAuth(USER, PASSWORD)
                          if emu.version == 1 else httpx.BasicAuth(USER, PASSWORD),
                          headers={"Accept": "application/hal+json;v=2.0"})
    doc = client.get("/rw/mastership/motion", params={"json": "1"} if emu.version == 1 else {}).json()
    items = doc["_embedded"]["_state"] if emu.version == 1 else doc["state"]
    assert items[0]["mastership"] == "internal"                      # RAPID runs and holds motion itself
    client.close()
    make_robot(emu).connect()


def test_rws2_over_tls_with_the_self_signed_certificate(make_emu, make_robot):
    pytest.importorskip("cryptography")
    emu = make_emu(2)
    assert emu.tls and emu.base_url.startswith("https://")
    robot = make_robot(emu, verify=emu.cert_path)                 # the controller's exported certificate
    robot.connect()
    assert robot.session.client.base_url.scheme == "https"
    robot.move_joints([3, 3, 3, 3, 3, 3])
    strict = make_robot(emu, verify=True, scheme="https")         # system CAs: the self-signed cert is refused
    with pytest.raises(ConnectionLost, match="no RWS server found"):
        strict.connect()


def test_speed_cap_reaches_rapid_and_nothing_above_it(emu, make_robot):
    robot = make_robot(emu, speed=[7000, 500, 5000, 1000])
    robot.set_motion_limits(MotionLimits(max_tcp_speed_mm_s=120.0, max_joint_speed_pct=40.0))
    robot.connect()
    robot.move_joints([10, 0, 0, 0, 30, 0])
    robot.move_linear([600, 50, 800], [0, 0, 1, 0])
    assert len(emu.executed) == 2
    for rec in emu.executed:
        assert rec["v_tcp_programmed"] <= 120.0 and rec["v_leax_programmed"] <= 120.0
        assert rec["vmax"] == 120.0 and rec["override"] == 40.0 and rec["v_tcp"] <= 120.0
    with emu._lock:                                               # a bypass of the driver: RAPID still clamps
        rec = emu._limits(emu.modules["calserver"].symbols, [7000.0, 500.0, 5000.0, 1000.0])
    assert rec["v_tcp"] <= 120.0 and rec["v_leax"] <= 120.0
    with pytest.raises(RobotError, match="motion limits"):
        robot.set_motion_limits(MotionLimits(max_tcp_speed_mm_s=-1.0))


def test_payload_is_the_loaddata_of_cal_tool(emu, robot):
    robot.set_payload(Payload(12.5, (0.0, 10.0, 80.0)))
    assert parse_literal(emu.symbol("cal_tool"))[2][:2] == [12.5, [0.0, 10.0, 80.0]]
    robot.move_joints([0, 10, 0, 0, 30, 0])
    assert emu.executed[-1]["load_kg"] == 12.5 and emu.executed[-1]["cog_mm"] == (0.0, 10.0, 80.0)
    robot.set_payload(Payload(0.0))
    assert parse_literal(emu.symbol("cal_tool"))[2][0] == pytest.approx(0.001)   # RAPID's minimum mass


def test_identity_override_and_absacc(make_emu, make_robot, version):
    emu = make_emu(version, absacc=True, serial="4600-501234", robot_type="IRB 4600-60/2.05")
    robot = make_robot(emu)
    robot.connect()
    ident = robot.identity()
    assert ident["vendor"] == "ABB" and ident["model"] == "IRB 4600-60/2.05" and ident["serial"] == "4600-501234"
    assert ident["controller_type"] == ("IRC5" if version == 1 else "OmniCore")
    assert ident["software_version"].startswith("RobotWare 6." if version == 1 else "RobotWare 7.")
    assert ident["absacc"] == "yes"
    assert robot.speed_override_pct() == 100.0
    emu.speedratio = 35
    assert robot.speed_override_pct() == 35.0
    plain = make_robot(make_emu(version))
    plain.connect()
    assert plain.identity()["absacc"] == "no"


def test_polling_never_exceeds_the_request_rate(make_emu, make_robot, version):
    """While waiting for a move the driver makes at most max_poll_rate_hz requests per second of its own
    pacing sleeps (counted requests against the sleeps it asked for: no wall-clock assertion)."""
    emu = make_emu(version, joint_speed_deg_s=400.0)
    slept = []
    robot = registry.open_robot(emu.url, {**FAST, "max_poll_rate_hz": 50.0, "poll_s": 0.001},
                                environ=ENV)
    robot._sleep = lambda s: (slept.append(s), time.sleep(s))
    robot.connect()
    before, slept[:] = len(emu.requests), []
    robot.move_joints([60, 0, 0, 0, 30, 0])                        # 0.15 s of motion
    polls = len(emu.requests) - before - 8                         # minus the request writes
    assert polls >= 2 and polls <= 50.0 * sum(slept) + 1
    robot.close()


def test_production_program_running_without_calserver_is_explained(make_emu, make_robot):
    emu = make_emu(1, customer_program="plain")                  # RAPID runs the production main, not cal_run
    assert emu.pp == ("MainModule", "main") and emu.execution == "stopped"
    emu.set_execution(True)
    with pytest.raises(RobotNotReady, match=r"program pointer is in MainModule/main: run cal_run"):
        make_robot(emu).connect()


def test_reloaded_calserver_gets_every_argument_again(emu, make_robot):
    """A module reload resets the PERS to their initial values (speed, caps, tool): the driver notices through
    cal_epoch before the next trigger and rewrites them, so the caps hold."""
    robot = make_robot(emu)
    robot.set_motion_limits(MotionLimits(max_tcp_speed_mm_s=80.0, max_joint_speed_pct=50.0))
    robot.set_payload(Payload(7.0, (0.0, 0.0, 40.0)))
    robot.connect()
    robot.move_joints([1, 1, 1, 1, 31, 1])
    for name, initial in (("cal_speed", "[200,100,5000,1000]"), ("cal_vmax", "250"), ("cal_override", "100"),
                          ("cal_epoch", "0"), ("cal_tool", "[TRUE,[[0,0,0],[1,0,0,0]],[0.001,[0,0,0.001],"
                                                            "[1,0,0,0],0,0,0]]")):
        emu.set_symbol(name, initial)                          # what a reload of the module does
    robot.move_joints([2, 2, 2, 2, 32, 2])
    rec = emu.executed[-1]
    assert rec["vmax"] == 80.0 and rec["v_tcp_programmed"] <= 80.0 and rec["override"] == 50.0
    assert rec["load_kg"] == 7.0
