"""emScon protocol, driver and emulator (drivers/emscon_protocol.py, drivers/emscon.py,
drivers/emulators/emscon_server.py).

Struct sizes are checked against the public header's layouts (pack(4), 4-byte long/enum); driver tests run against
the emulator on 127.0.0.1 with small timeouts; the third-party client ``cesapi`` (PyPI) checks the emulator.
"""
from __future__ import annotations

import math
import threading
import time

import pytest

from drivers import emscon_protocol as P
from drivers.base import BeamBroken, ConnectionLost, DriverError, GarbageReply, TargetNotFound, TrackerTimeout
from drivers.emscon import EmsconSettings, EmsconTracker, NotReady, open_tracker, parse_url, status_error
from drivers.emulators.emscon_server import DEFAULT_POINT_MM, EmsconDevice, EmsconEmulator, NoiseModel
from drivers.registry import open_tracker as registry_open_tracker
from tests.drivers.helpers import served_port

T = 0.3
FAST = {"timeout_s": T, "meas_time_ms": 10}


@pytest.fixture(autouse=True)
def no_leftover_threads():
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if not left:
            return
        time.sleep(0.02)
    assert not left, f"threads left running: {left}"


# ---------------------------------------------------------------------------------------------- protocol (unit)

@pytest.mark.unit
def test_struct_sizes_match_the_header_layout():
    # SingleMeasResultT: ReturnDataT (12) + measMode, bIsTryMode (8) + 17 doubles; ...Result2T: 23 doubles
    assert P.SINGLE_MEAS.size == 156 and P.SINGLE_MEAS2.size == 204
    assert P.COMMAND_CT.size == 12 and P.COMMAND_RT.size == 16 and P.ERROR_RESPONSE.size == 16
    assert P.COMMAND_RT.size + P.RESULTS[P.C_GET_SYSTEM_STATUS].size == 56          # GetSystemStatusRT
    assert P.COMMAND_RT.size + P.RESULTS[P.C_GET_REFLECTORS].size == 100            # GetReflectorsRT
    assert len(P.encode_command(P.C_GO_POSITION, 1.0, 2.0, 3.0, 1)) == 12 + 28       # GoPositionCT
    assert len(P.encode_command(P.C_SET_SYSTEM_SETTINGS, *[0] * 9)) == 12 + 36


@pytest.mark.unit
def test_command_bytes_are_little_endian_with_size_first():
    data = P.encode_command(P.C_SET_UNITS, 1, 1, 0, 0, 0)
    assert data[:12] == (32).to_bytes(4, "little") + (0).to_bytes(4, "little") + (5).to_bytes(4, "little")
    assert P.decode_command(data) == (P.C_SET_UNITS, (1, 1, 0, 0, 0))
    with pytest.raises(P.FramingError):
        P.decode_command(data[:-4])


@pytest.mark.unit
@pytest.mark.parametrize("extended", [False, True])
def test_measurement_result_round_trip(extended):
    data = P.encode_meas_result((1.5, -2.5, 3.25), (0.004, 0.005, 0.006), (1e-6, -2e-6, 3e-6), (21.0, 1001.0, 40.0),
                                extended=extended)
    r = P.decode_packet(data)
    assert isinstance(r, P.MeasResult) and r.extended is extended and r.status == P.RS_ALL_OK
    assert r.values == (1.5, -2.5, 3.25) and r.std == (0.004, 0.005, 0.006)
    assert r.environment == (21.0, 1001.0, 40.0)
    assert r.covar == ((1e-6, -2e-6, 3e-6) if extended else (0.0, 0.0, 0.0))
    assert r.std_total == pytest.approx(math.sqrt(0.004**2 + 0.005**2 + 0.006**2))


@pytest.mark.unit
def test_reader_cuts_packets_across_chunks_and_rejects_junk():
    a = P.encode_reply(P.C_INITIALIZE, P.RS_ALL_OK)
    b = P.encode_status_change(P.SSC_MEAS_STATUS_READY)
    stream = a + b
    reader = P.PacketReader()
    got = []
    for i in range(len(stream)):                     # one byte at a time
        reader.feed(stream[i:i + 1])
        while (packet := reader.next_packet()) is not None:
            got.append(P.decode_packet(packet))
    assert got == [P.CommandReply(P.C_INITIALIZE, P.RS_ALL_OK, b""), P.StatusChange(P.SSC_MEAS_STATUS_READY)]
    reader.feed(b"\xff\xff\xff\x7fjunkjunkjunk")
    with pytest.raises(P.FramingError, match="not an emScon packet"):
        reader.next_packet()


@pytest.mark.unit
@pytest.mark.parametrize("status, kind", [(10004, "beam_broken"), (10014, "beam_broken"), (10009, "beam_broken"),
                                          (39, "not_initialised"), (10012, "not_ready"), (10013, "unstable"),
                                          (57, "error")])
def test_status_codes_map_to_error_kinds(status, kind):
    exc = status_error(status, "emscon://x")
    assert exc.kind == kind and str(status) in str(exc) and "\n" not in str(exc)


@pytest.mark.unit
@pytest.mark.parametrize("options, key", [({"timeout_s": 0}, "timeout_s"), ({"meas_time_ms": 0.5}, "meas_time_ms"),
                                          ({"environment": {"temp_c": 20}}, "environment"),
                                          ({"statistic": "full"}, "statistic"), ({"colour": 1}, "colour"),
                                          ({"use_adm": "yes"}, "use_adm")])
def test_bad_options_name_the_option(options, key):
    with pytest.raises(DriverError, match=key):
        EmsconSettings.from_options(options)


@pytest.mark.unit
def test_url_parsing():
    assert parse_url("emscon://192.168.0.1") == ("192.168.0.1", 700)
    assert parse_url("emscon://tracker.local:7000") == ("tracker.local", 7000)
    with pytest.raises(DriverError, match="emscon://HOST"):
        parse_url("emscon://")
    assert isinstance(registry_open_tracker("emscon://127.0.0.1:1", {}), EmsconTracker)


@pytest.mark.unit
def test_noise_model_is_range_along_the_line_of_sight():
    cov = NoiseModel(range_a_um=1.0, range_b_um_per_m=0.0, transverse_a_um=10.0,
                     transverse_b_um_per_m=0.0).covariance_mm2((3000.0, 0.0, 0.0))
    assert cov[0][0] == pytest.approx(1e-6) and cov[1][1] == pytest.approx(1e-4) and cov[2][2] == pytest.approx(1e-4)


# ------------------------------------------------------------------------------------------ driver vs emulator

@pytest.mark.system
def test_connect_initialises_configures_and_measures():
    truth = (1800.0, 700.0, -250.0)
    with EmsconEmulator(lambda: truth, seed=1) as emu:
        with open_tracker(emu.url, dict(FAST, reflector="RRR 0.5in")) as tracker:
            r = tracker.measure()
            env = tracker.environment()
        device = emu.device
    assert device.initialised and device.units == (1, 1, 0, 0, 0) and device.meas_time_ms == 10
    assert device.statistic_mode == P.SM_EXTENDED and device.reflector_id == 2
    assert device.settings[:5] == [P.WMS_READ_AND_CALCULATE, 0, 0, 1, 1]
    assert P.C_INITIALIZE in device.commands
    assert r.xyz_mm == pytest.approx(device.last_truth["measured_mm"], abs=1e-9)
    assert r.xyz_mm == pytest.approx(truth, abs=0.05)
    cov = device.last_truth["cov_mm2"]
    assert r.extra["std_y_mm"] == pytest.approx(math.sqrt(cov[1][1]))
    assert r.extra["cov_xz_mm2"] == pytest.approx(cov[0][2])
    assert env == {"temp_c": 20.5, "pressure_hpa": 1008.0, "humidity_pct": 42.0}
    assert tracker.identity()["serial"] == "754321" and "RRR05" in tracker.reflector_name


@pytest.mark.system
def test_manual_environment_and_standard_statistics():
    options = dict(FAST, environment={"temp_c": 18.5, "pressure_hpa": 990.0, "humidity_pct": 55.0},
                   statistic="standard")
    with EmsconEmulator(initialised=True) as emu:
        with open_tracker(emu.url, options) as tracker:
            r = tracker.measure()
        assert P.C_INITIALIZE not in emu.device.commands           # already initialised: not re-initialised
    assert r.extra["temp_c"] == 18.5 and r.extra["pressure_hpa"] == 990.0 and r.extra["humidity_pct"] == 55.0
    assert "cov_xy_mm2" not in r.extra and r.extra["std_x_mm"] > 0


@pytest.mark.system
def test_unknown_reflector_is_a_one_line_error():
    with EmsconEmulator() as emu:
        with pytest.raises(DriverError, match="reflector 'RRR 9in' not known.*RRR 1.5in"):
            open_tracker(emu.url, dict(FAST, reflector="RRR 9in")).connect()


@pytest.mark.system
def test_beam_break_then_reacquire_needs_aiming():
    """After a break the tracker points at the previous position: FindReflector alone fails, GoPosition + Find works."""
    where = [(2000.0, 0.0, 0.0)]
    with EmsconEmulator(lambda: where[0]) as emu:
        with open_tracker(emu.url, FAST) as tracker:
            tracker.measure()
            where[0] = (2000.0, 500.0, 0.0)                      # the robot moved 500 mm
            emu.inject("beam_break")
            with pytest.raises(BeamBroken):
                tracker.measure()
            with pytest.raises(BeamBroken):                      # stays broken
                tracker.measure()
            with pytest.raises(TargetNotFound):                  # aimed at the wrong place: not found
                tracker.reacquire((2000.0, 0.0, 0.0))
            tracker.reacquire((2000.0, 480.0, 10.0))             # within the search radius
            assert tracker.measure().xyz_mm == pytest.approx(where[0], abs=0.05)
            steps = [e["step"] for e in tracker.drain_events()]
    assert steps == ["go_position", "find_reflector", "reacquire_failed", "go_position", "find_reflector",
                     "reacquired"]


@pytest.mark.system
@pytest.mark.parametrize("fault, step", [("garbage", "reconnect"), ("disconnect", "reconnect"),
                                         ("not_initialised", "initialize")])
def test_recoverable_faults(fault, step):
    with EmsconEmulator() as emu:
        with open_tracker(emu.url, FAST) as tracker:
            emu.inject(fault)
            t0 = time.monotonic()
            try:
                tracker.measure()
            except GarbageReply:
                assert fault == "garbage"
            r = tracker.measure()
            assert time.monotonic() - t0 < 3.0
            assert r.xyz_mm == pytest.approx(DEFAULT_POINT_MM, abs=0.05)
            assert step in [e["step"] for e in tracker.drain_events()]


@pytest.mark.system
def test_late_result_times_out_and_is_discarded():
    calls = []

    def source():
        calls.append(len(calls) + 1)
        return (1000.0 * len(calls), 0.0, 0.0)
    with EmsconEmulator(source, late_s=T + 0.15) as emu:          # beyond the result wait of T + 10 ms
        with open_tracker(emu.url, FAST) as tracker:
            emu.inject("late")
            t0 = time.monotonic()
            with pytest.raises(TrackerTimeout):
                tracker.measure()
            assert time.monotonic() - t0 < T + 0.01 + 1.0
            r = tracker.measure()                               # the late result (x=1000) is not taken for this one
            assert r.xyz_mm[0] == pytest.approx(2000.0, abs=0.05) and tracker.stale_discarded == 1


@pytest.mark.system
def test_warm_up_is_a_retryable_not_ready_error():
    with EmsconEmulator() as emu:
        with open_tracker(emu.url, FAST) as tracker:
            emu.inject("warm_up")
            with pytest.raises(NotReady, match="SensorNotWarmedUp"):
                tracker.measure()
            tracker.measure()


@pytest.mark.system
def test_connection_refused_is_connection_lost():
    with EmsconEmulator() as emu:
        url = emu.url
    with pytest.raises(ConnectionLost, match="cannot connect"):
        open_tracker(url, dict(FAST, connect_timeout_s=1.0)).connect()


@pytest.mark.unit
def test_emulator_honours_units_in_results_and_reflector_offsets():
    device = EmsconDevice(lambda: (1000.0, 0.0, 0.0), initialised=True, noise=NoiseModel(0, 0, 0, 0))
    device.respond(P.encode_command(P.C_SET_UNITS, 0, 1, 1, 2, 0))           # m, deg, F, kPa
    reply, result = device.respond(P.encode_command(P.C_START_MEASUREMENT))
    r = P.decode_packet(result.data)
    assert r.values == pytest.approx((1.0, 0.0, 0.0)) and r.environment[0] == pytest.approx(20.5 * 1.8 + 32)
    assert r.environment[1] == pytest.approx(100.8)
    first = P.decode_packet(device.respond(P.encode_command(P.C_GET_REFLECTORS))[0].data)
    assert P.RESULTS[P.C_GET_REFLECTORS].unpack_from(first.payload)[3] == pytest.approx(0.01905)


# ---------------------------------------------------------------------------------- third-party client (cesapi)

@pytest.mark.system
def test_cesapi_client_initialises_configures_measures_and_decodes():
    """cesapi's CommandSync (a client written independently of this project) drives the emulator."""
    from CESAPI import command as cesapi_command, connection as cesapi_connection, packet as cesapi_packet

    truth = (3120.5, -845.25, 410.125)
    with EmsconEmulator(lambda: truth, seed=3, environment=(19.75, 1002.5, 37.0)) as emu:
        conn = cesapi_connection.Connection()
        try:
            conn.connect(host="127.0.0.1", port=emu.port)
            sync = cesapi_command.CommandSync(conn)
            status = sync.GetSystemStatus()
            assert status.trackerProcessorStatus != cesapi_packet.ES_TPS_Initialized
            sync.Initialize()
            units = cesapi_packet.SystemUnitsDataT()
            units.lenUnitType = cesapi_packet.ES_LU_Millimeter
            units.angUnitType = cesapi_packet.ES_AU_Degree
            units.tempUnitType = cesapi_packet.ES_TU_Celsius
            units.pressUnitType = cesapi_packet.ES_PU_Mbar
            units.humUnitType = cesapi_packet.ES_HU_RH
            sync.SetUnits(units)
            sync.SetMeasurementMode(cesapi_packet.ES_MM_Stationary)
            result = sync.StartMeasurement()
            last = emu.device.last_truth
            assert sync.GetSystemStatus().trackerProcessorStatus == cesapi_packet.ES_TPS_Initialized
            sync.SetStatisticMode(cesapi_packet.ES_SM_Standard, cesapi_packet.ES_SM_Extended)  # continuous, stationary
            result2 = sync.StartMeasurement()                                  # SingleMeasResult2T, with covariances
            last2 = emu.device.last_truth
        finally:
            conn.disconnect()
    measured = (result.dVal1, result.dVal2, result.dVal3)
    assert measured == pytest.approx(last["measured_mm"], abs=1e-9)           # decoded bit for bit
    assert measured == pytest.approx(truth, abs=0.05)                           # and it is the SMR
    cov = last["cov_mm2"]
    assert (result.dStd1, result.dStd2, result.dStd3) == pytest.approx([math.sqrt(cov[i][i]) for i in range(3)])
    assert (result.dTemperature, result.dPressure, result.dHumidity) == (19.75, 1002.5, 37.0)
    assert (result2.dVal1, result2.dVal2, result2.dVal3) == pytest.approx(last2["measured_mm"], abs=1e-9)
    cov2 = last2["cov_mm2"]
    assert (result2.dCovar12, result2.dCovar13, result2.dCovar23) == pytest.approx(
        (cov2[0][1], cov2[0][2], cov2[1][2]), rel=1e-12) and abs(cov2[0][1]) > 0
    assert (result2.dTemperature, result2.dPressure, result2.dHumidity) == (19.75, 1002.5, 37.0)


# ------------------------------------------------------------------------------------------------- command line

@pytest.mark.unit
@pytest.mark.parametrize("url, options, text", [
    ("emscon://127.0.0.1:1", {"meas_time_ms": "long"}, "emscon option 'meas_time_ms'"),
    ("tracker+socket://127.0.0.1:1", {"colour": 1}, "tracker option 'colour'")])
def test_bad_tracker_options_are_input_errors_at_the_cli(tmp_path, capsys, url, options, text):
    from campaign.cli import main
    from tests.campaign.helpers import small_config

    cfg = small_config(tmp_path, **{"tracker.url": url, "tracker.options": options})
    assert main(["run", str(cfg), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and text in err and not (tmp_path / "run").exists()
