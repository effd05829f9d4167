"""Tests of the generic line-protocol tracker driver (drivers/line_tracker.py) and its TCP emulator.

Codec tests are in test_line_codec.py. Driver tests run over pyserial's ``loop://`` (the command echoes back,
so a command that *is* a reply exercises framing without a device), a pty (native serial path) and the emulator on
127.0.0.1. Every timeout is small (0.2 s) and every RNG is seeded.
"""
from __future__ import annotations

import itertools
import math
import os
import re
import select
import threading
import time
from pathlib import Path

import pytest
import serial

from drivers.base import (BeamBroken, ConnectionLost, GarbageReply, TargetNotFound, Tracker, TrackerError,
                          TrackerTimeout, Unstable)
from drivers.emulators.line_tracker_server import DEFAULT_POINT_MM, Faults, SampleDevice, TrackerEmulator
from drivers.registry import open_tracker as registry_open_tracker
from drivers.line_profile import LineProfile, SensorProfile
from drivers.line_tracker import LineSensor, LineTracker, NoReply, open_tracker
from drivers.line_codec import average_readings
from tests.drivers.helpers import served_port

pytestmark = pytest.mark.system

REPO = Path(__file__).resolve().parents[2]
T = 0.2  # request timeout used throughout (s)
SLACK = 3.0  # scheduling tolerance on elapsed-time upper bounds (s): they prove 'never hangs', not speed
LOOP = {"init": [], "environment": None, "timeout_s": T}


def wait_until(condition, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not reached in time"
        time.sleep(0.005)


def counter_source():
    """Position source returning (n, 0, 0) mm on its n-th call: tells which request a reply belongs to."""
    counter = itertools.count(1)
    return lambda: (float(next(counter)), 0.0, 0.0)


@pytest.fixture(autouse=True)
def no_leftover_threads():
    before = set(threading.enumerate())
    yield
    left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
    assert not left, f"threads left running: {left}"


@pytest.fixture
def emulator():
    with TrackerEmulator(seed=0) as emu:
        yield emu


def measure_error(tracker: LineTracker) -> TrackerError | ConnectionLost:
    with pytest.raises((TrackerError, ConnectionLost)) as info:
        tracker.measure()
    assert "\n" not in str(info.value)
    return info.value


# ------------------------------------------------------------------------------------------- driver over loop://

class Recorder:
    """An opener that remembers the ports it opened (to pre-load the loopback with stale lines)."""

    def __init__(self) -> None:
        self.ports = []

    def __call__(self, url, **kwargs):
        port = serial.serial_for_url(url, **kwargs)
        self.ports.append(port)
        return port


def loop_tracker(opener=serial.serial_for_url, **options) -> LineTracker:
    return LineTracker("tracker+loop://", LineProfile.from_options({**LOOP, **options}), opener=opener)


def test_registry_returns_a_line_tracker():
    tracker = registry_open_tracker("tracker+loop://", {"init": []}, world=None)
    assert isinstance(tracker, LineTracker) and isinstance(tracker, Tracker)


def test_loop_reading_with_units_and_clock():
    class Clock:
        def now(self):
            return 42.0

    profile = LineProfile.from_options({**LOOP, "measure": "OK {seq} 1.5 -2 3 0.001 0.002 0.003", "length_unit": "m"})
    with LineTracker("tracker+loop://", profile, clock=Clock()) as tracker:
        reading = tracker.measure()
    assert reading.xyz_mm == (1500.0, -2000.0, 3000.0) and reading.t_s == 42.0
    assert reading.extra == pytest.approx({"sx_mm": 1.0, "sy_mm": 2.0, "sz_mm": 3.0})


@pytest.mark.parametrize("reply, exc", [("ERR {seq} BEAM_BROKEN", BeamBroken), ("ERR {seq} NO_TARGET", TargetNotFound),
                                        ("ERR {seq} UNSTABLE", Unstable), ("ERR {seq} TIMEOUT", TrackerTimeout),
                                        ("#%!? {seq}", GarbageReply)])
def test_loop_device_errors(reply, exc):
    with loop_tracker(measure=reply) as tracker:
        err = measure_error(tracker)
    assert type(err) is exc


def test_loop_partial_line_times_out_within_the_timeout():
    with loop_tracker(tx_terminator="\n", rx_terminator="\r\n", measure="OK {seq} 1 2 3") as tracker:
        t0 = time.monotonic()
        err = measure_error(tracker)
        elapsed = time.monotonic() - t0
    assert isinstance(err, NoReply) and isinstance(err, TrackerTimeout)
    assert T <= elapsed < T + SLACK


def test_loop_retries_bound_the_total_time():
    with loop_tracker(tx_terminator="\n", rx_terminator="\r\n", measure="OK {seq} 1 2 3", retries=2) as tracker:
        t0 = time.monotonic()
        measure_error(tracker)
        elapsed = time.monotonic() - t0
    assert 3 * T <= elapsed < 3 * T + SLACK


def test_loop_stale_line_is_dropped_by_seq_without_flush():
    recorder = Recorder()
    with loop_tracker(recorder, measure="OK {seq} 1 2 3", flush=False) as tracker:
        recorder.ports[0].write(b"OK 0 9 9 9\r\nERR 0 BEAM_BROKEN\r\n")   # late replies to an earlier request
        assert tracker.measure().xyz_mm == (1.0, 2.0, 3.0)
        assert tracker.stale_discarded == 2


def test_seq_placeholder_may_be_formatted():
    recorder = Recorder()
    with loop_tracker(recorder, measure="OK {seq:04d} 1 2 3", flush=False) as tracker:
        recorder.ports[0].write(b"OK 0000 9 9 9\r\n")
        assert tracker.measure().xyz_mm == (1.0, 2.0, 3.0) and tracker.stale_discarded == 1


def test_loop_flush_drops_stale_input():
    recorder = Recorder()
    with loop_tracker(recorder, measure="OK 1 2 3", measure_regex=r"^OK (?P<x>\S+) (?P<y>\S+) (?P<z>\S+)$") as tracker:
        recorder.ports[0].write(b"#%! junk\r\nOK 9 9 9\r\n")
        assert tracker.measure().xyz_mm == (1.0, 2.0, 3.0)
        assert tracker.stale_discarded == 0


def test_loop_init_checks_reply():
    with loop_tracker(init=["READY"], measure="OK {seq} 1 2 3") as tracker:   # the echo of READY is the reply
        assert tracker.measure().xyz_mm == (1.0, 2.0, 3.0)
    tracker = loop_tracker(init=["HELLO"])
    with pytest.raises(GarbageReply, match="HELLO"):
        tracker.connect()
    with pytest.raises(ConnectionLost, match="not connected"):
        tracker.measure()


def test_loop_init_without_reply_check_and_stop_on_close():
    recorder = Recorder()
    tracker = loop_tracker(recorder, init=["UNITS mm", "MODE {seq}"], init_regex=None, stop="STOP")
    tracker.connect()
    port = recorder.ports[0]
    assert port.read(port.in_waiting) == b"UNITS mm\r\nMODE 2\r\n"
    tracker.close()
    tracker.close()   # idempotent
    assert not port.is_open


def test_measure_before_connect_and_after_close_is_connection_lost():
    tracker = loop_tracker()
    with pytest.raises(ConnectionLost):
        tracker.measure()
    tracker.connect()
    tracker.close()
    with pytest.raises(ConnectionLost):
        tracker.measure()


def test_serial_exception_becomes_connection_lost():
    recorder = Recorder()
    with loop_tracker(recorder, measure="OK {seq} 1 2 3") as tracker:
        recorder.ports[0].close()   # the port goes away under the driver
        err = measure_error(tracker)
    assert isinstance(err, ConnectionLost)


def test_loop_environment_and_sensor_merge():
    options = {"environment": "ENV 21.5 1001.0 40", "sensor_url": "tracker+loop://", "sensor_prefix": "air_",
               "sensor_command": "T=68.0F P=29.92", "sensor_regex": r"^T=(?P<temp_f>{num})F P=(?P<pressure_inhg>{num})$"}
    with loop_tracker(**options) as tracker:
        env = tracker.environment()
    assert env == pytest.approx({"temp_c": 21.5, "pressure_hpa": 1001.0, "humidity_pct": 40.0,
                                 "air_temp_c": 20.0, "air_pressure_hpa": 29.92 * 33.8639})


def test_environment_is_empty_without_a_source():
    with loop_tracker() as tracker:
        assert tracker.environment() == {}


def test_sensor_timeout_and_garbage():
    def sensor(command):
        return LineSensor(SensorProfile("tracker+loop://", command, re.compile(r"^T (?P<temp_c>\S+)$"), "\r\n",
                                        "ascii", T, ""))

    s = sensor(None)   # listen-only, nothing arrives
    s.connect()
    t0 = time.monotonic()
    with pytest.raises(TrackerTimeout):
        s.read()
    assert time.monotonic() - t0 < T + SLACK
    s.close()
    s = sensor("HUMIDITY?")
    s.connect()
    with pytest.raises(GarbageReply, match="HUMIDITY"):
        s.read()
    s.close()


# -------------------------------------------------------------------------------------------- driver over a pty

@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")
def test_native_serial_path_over_a_pty():
    master, slave = os.openpty()
    device, stop = SampleDevice(lambda: (1.0, 2.0, 3.0)), threading.Event()

    def serve():
        buf = b""
        while not stop.is_set():
            if select.select([master], [], [], 0.02)[0]:
                buf += os.read(master, 1024)
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    os.write(master, device.respond(line.decode().strip()).data)

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        url = f"tracker+serial://{os.ttyname(slave)}?baudrate=115200"
        with open_tracker(url, {"timeout_s": 1.0}) as tracker:
            assert tracker.measure().xyz_mm == (1.0, 2.0, 3.0)
            assert tracker.environment()["temp_c"] == 20.0
    finally:
        stop.set()
        thread.join(2)
        os.close(master)
        os.close(slave)


# ------------------------------------------------------------------------------------------ driver vs emulator

def driver(emu: TrackerEmulator, **options) -> LineTracker:
    """A (not yet connected) driver for the emulator with the small test timeout."""
    return open_tracker(emu.url, {"timeout_s": T, **options})


def test_emulator_readings_with_default_options(emulator):
    tracker = open_tracker(emulator.url, {})
    with tracker:
        readings = [tracker.measure() for _ in range(5)]
    for r in readings:
        assert r.xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.02)
        assert r.extra == {"sx_mm": 0.005, "sy_mm": 0.005, "sz_mm": 0.005}
    assert [r.t_s for r in readings] == sorted(r.t_s for r in readings)
    mean, spread = average_readings(readings, stability_mm=0.02)
    assert mean == pytest.approx(DEFAULT_POINT_MM, abs=0.005) and 0 < spread < 0.02
    assert emulator.device.requests[0] == "INIT"


def test_emulator_position_source_and_environment():
    with TrackerEmulator(position_source=counter_source(), environment=(21.25, 998.5, 38.0)) as emu:
        with driver(emu) as tracker:
            assert [tracker.measure().xyz_mm[0] for _ in range(3)] == [1.0, 2.0, 3.0]
            assert tracker.environment() == {"temp_c": 21.25, "pressure_hpa": 998.5, "humidity_pct": 38.0}


def test_emulator_spherical_mode():
    profile = {"measure_regex": r"^OK (?P<seq>\d+) (?P<r>{num}) (?P<az>{num}) (?P<zen>{num})$", "angle_unit": "deg"}
    with TrackerEmulator(position_source=lambda: (1200.0, -900.0, 350.0), mode="spherical") as emu:
        with driver(emu, **profile) as tracker:
            assert tracker.measure().xyz_mm == pytest.approx((1200.0, -900.0, 350.0), abs=1e-4)


@pytest.mark.parametrize("fault, exc", [("beam_break", BeamBroken), ("no_target", TargetNotFound),
                                        ("unstable", Unstable), ("garbage", GarbageReply)])
def test_emulator_faults_map_to_errors_and_recover(emulator, fault, exc):
    with driver(emulator) as tracker:
        emulator.inject(fault)
        assert type(measure_error(tracker)) is exc
        assert tracker.measure().xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.02)


def test_emulator_dropped_reply_times_out_within_the_timeout(emulator):
    with driver(emulator) as tracker:
        emulator.inject("drop")
        t0 = time.monotonic()
        assert isinstance(measure_error(tracker), TrackerTimeout)
        assert T <= time.monotonic() - t0 < T + SLACK


def test_emulator_dropped_reply_is_retried(emulator):
    with driver(emulator, retries=1) as tracker:
        emulator.inject("drop")
        t0 = time.monotonic()
        assert tracker.measure().xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.02)
        assert T <= time.monotonic() - t0 < T + SLACK


def test_emulator_late_reply_in_flight_is_dropped_by_seq():
    """The late reply to request 1 arrives while request 2 is pending: recognised by its seq and dropped.
    A longer timeout than T here: request 2's reply must arrive within it after the late reply (load-proof)."""
    timeout_s = 1.0
    with TrackerEmulator(position_source=counter_source(), faults={"delay_s": timeout_s + 0.2}) as emu:
        with open_tracker(emu.url, {"timeout_s": timeout_s}) as tracker:
            emu.inject("delay")
            assert isinstance(measure_error(tracker), TrackerTimeout)
            assert emu.replies_sent == 1           # READY only: the late reply is still pending
            assert tracker.measure().xyz_mm == (2.0, 0.0, 0.0)
            assert tracker.stale_discarded == 1


def test_emulator_late_reply_already_arrived_is_flushed():
    with TrackerEmulator(position_source=counter_source(), faults={"delay_s": T + 0.05}) as emu:
        with driver(emu) as tracker:
            emu.inject("delay")
            measure_error(tracker)
            wait_until(lambda: emu.replies_sent == 2)   # the late reply is now waiting in the socket
            assert tracker.measure().xyz_mm == (2.0, 0.0, 0.0)
            assert tracker.stale_discarded == 0


def test_emulator_late_reply_without_flush_is_dropped_by_seq():
    with TrackerEmulator(position_source=counter_source(), faults={"delay_s": T + 0.05}) as emu:
        with driver(emu, flush=False) as tracker:
            emu.inject("delay")
            measure_error(tracker)
            wait_until(lambda: emu.replies_sent == 2)
            assert tracker.measure().xyz_mm == (2.0, 0.0, 0.0)
            assert tracker.stale_discarded == 1


def test_emulator_disconnect_is_connection_lost_and_reconnect_works(emulator):
    tracker = driver(emulator)
    tracker.connect()
    emulator.inject("disconnect")
    assert isinstance(measure_error(tracker), ConnectionLost)
    assert isinstance(measure_error(tracker), ConnectionLost)    # stays disconnected until connect()
    tracker.connect()
    assert tracker.measure().xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.02)
    tracker.close()
    assert emulator.connections == 2


def test_connection_refused_is_connection_lost():
    with TrackerEmulator() as emu:
        url = emu.url
    with pytest.raises(ConnectionLost, match="cannot open"):
        open_tracker(url, {"timeout_s": T}).connect()


def test_emulator_random_faults_are_seeded():
    def outcomes(seed):
        with TrackerEmulator(seed=seed, faults={"beam_break": 0.3, "garbage": 0.2}) as emu:
            with driver(emu) as tracker:
                return [_outcome(tracker) for _ in range(20)]
    first = outcomes(3)
    assert first == outcomes(3)
    assert {"ok", "beam_broken", "garbage"} <= set(first)


def _outcome(tracker):
    try:
        tracker.measure()
        return "ok"
    except TrackerError as exc:
        return exc.kind


def test_emulator_fault_settings_are_validated():
    with pytest.raises(ValueError, match="beam_break"):
        Faults(beam_break=1.5)
    with pytest.raises(ValueError, match="fire"):
        SampleDevice(faults={"fire": 0.1})
    with pytest.raises(ValueError, match="fire"):
        SampleDevice().inject("fire")
    device = SampleDevice()
    device.set_faults(drop=1.0)
    assert device.respond("MEAS 1").data == b"" and device.respond("MEAS").data == b""
    assert device.respond("FOO").data == b"ERR - UNKNOWN_COMMAND\r\n"
    assert device.respond("INIT").data == b"READY\r\n" and device.respond("STOP").data == b"STOPPED\r\n"


def test_sample_protocol_without_seq():
    device = SampleDevice(lambda: (1.0, 2.0, 3.0))
    assert device.respond("MEAS").data == b"OK 1.00000 2.00000 3.00000 0.00500 0.00500 0.00500\r\n"
    device.inject("beam_break")
    assert device.respond("MEAS").data == b"ERR BEAM_BROKEN\r\n"


def test_emulator_command_line_prints_port_and_stops_on_stdin_eof():
    with served_port("drivers.emulators.line_tracker_server", "--seed", "1") as (proc, port):
        with open_tracker(f"tracker+socket://127.0.0.1:{port}", {"timeout_s": 1.0}) as tracker:
            assert tracker.measure().xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.02)
        proc.stdin.close()
        assert proc.wait(5) == 0


def test_documented_example_options_are_valid():
    yaml = pytest.importorskip("yaml")
    text = (REPO / "docs" / "drivers_tracker.md").read_text(encoding="utf-8")
    blocks = [b.split("```", 1)[0] for b in text.split("```yaml")[1:]]
    assert blocks
    for block in blocks:
        cell = yaml.safe_load(block)["tracker"]
        tracker = open_tracker(cell["url"], cell["options"])
        assert tracker.profile.coords == "spherical" and tracker.profile.sensor.prefix == "air_"
        c = tracker.codec
        xyz, extra = c.reading(c.parse_measure("OK;3;2.5;50;100;20.5;1001.2;41", 3).groups)
        assert xyz == pytest.approx((2500 / math.sqrt(2), -2500 / math.sqrt(2), 0.0), abs=1e-9)
        assert extra == pytest.approx({"temp_c": 20.5, "pressure_hpa": 1001.2, "humidity_pct": 41.0})
