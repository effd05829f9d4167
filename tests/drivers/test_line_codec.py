"""Tests of the line-protocol tracker codec and profile (drivers/line_codec.py, drivers/line_profile.py).

Pure: every test runs on strings and option mappings, without a port or a device.
"""
from __future__ import annotations

import math

import pytest

from drivers.base import (BeamBroken, GarbageReply, TargetNotFound, TrackerError, TrackerReading, TrackerTimeout,
                          Unstable)
from drivers.line_profile import LineProfile, port_spec
from drivers.line_codec import Reply, TrackerCodec, average_readings, spherical_to_xyz
from drivers.line_tracker import open_tracker

pytestmark = pytest.mark.unit


def codec(**options) -> TrackerCodec:
    return TrackerCodec(LineProfile.from_options(options))


# ------------------------------------------------------------------------------------------------------- codec

def test_default_profile_parses_cartesian_reply_with_device_std():
    c = codec()
    reply = c.parse_measure("OK 7 1500.25 -250.5 1200 0.004 0.005 0.006", seq=7)
    assert reply.kind == "ok"
    xyz, extra = c.reading(reply.groups)
    assert xyz == (1500.25, -250.5, 1200.0)
    assert extra == {"sx_mm": 0.004, "sy_mm": 0.005, "sz_mm": 0.006}


def test_command_appends_terminator_unless_template_has_it():
    assert codec().command("MEAS {seq}", 12) == b"MEAS 12\r\n"
    assert codec().command("MEAS\r\n", 1) == b"MEAS\r\n"
    assert codec(tx_terminator="\r").command("MEAS {seq}", 3) == b"MEAS 3\r"


@pytest.mark.parametrize("unit, factor", [("mm", 1.0), ("m", 1000.0), ("um", 1e-3), ("in", 25.4), ("inch", 25.4),
                                          ("ft", 304.8)])
def test_length_units_convert_to_mm(unit, factor):
    c = codec(length_unit=unit)
    xyz, extra = c.reading(c.parse_measure("OK 1 1.5 -2 0.25 0.001 0.001 0.001", 1).groups)
    assert xyz == pytest.approx((1.5 * factor, -2 * factor, 0.25 * factor))
    assert extra["sx_mm"] == pytest.approx(0.001 * factor)


SPHERICAL = r"^P (?P<r>{num}) (?P<az>{num}) (?P<zen>{num})$"


@pytest.mark.parametrize("unit, per_rad", [("deg", 180 / math.pi), ("rad", 1.0), ("gon", 200 / math.pi)])
def test_spherical_az_zen_in_each_angle_unit(unit, per_rad):
    r_mm, az, zen = 3000.0, math.radians(30.0), math.radians(70.0)
    c = codec(measure="P", measure_regex=SPHERICAL, angle_unit=unit, length_unit="m")
    line = f"P {r_mm / 1000:.9f} {az * per_rad:.12f} {zen * per_rad:.12f}"
    xyz, _ = c.reading(c.parse_measure(line).groups)
    expected = (r_mm * math.sin(zen) * math.cos(az), r_mm * math.sin(zen) * math.sin(az), r_mm * math.cos(zen))
    assert xyz == pytest.approx(expected, abs=1e-6)
    assert c.profile.coords == "spherical"


def test_spherical_hz_v_with_declared_conventions():
    regex = r"^(?P<hz>{num}),(?P<v>{num}),(?P<r>{num})$"
    c = codec(measure="M", measure_regex=regex, angle_unit="gon", azimuth_sense="cw", vertical_zero="horizon")
    xyz, _ = c.reading(c.parse_measure("50,0,2000").groups)   # hz 50 gon clockwise = az -45 deg, on the horizon
    assert xyz == pytest.approx((2000 / math.sqrt(2), -2000 / math.sqrt(2), 0.0), abs=1e-9)
    c = codec(measure="M", measure_regex=regex, angle_unit="deg", azimuth_sense="ccw", vertical_zero="zenith")
    assert c.reading(c.parse_measure("90,90,10").groups)[0] == pytest.approx((0.0, 10.0, 0.0), abs=1e-12)


def test_spherical_helper_matches_documented_formula():
    assert spherical_to_xyz(2.0, 0.0, math.pi / 2) == pytest.approx((2.0, 0.0, 0.0))
    assert spherical_to_xyz(2.0, 0.0, 0.0) == pytest.approx((0.0, 0.0, 2.0))


@pytest.mark.parametrize("line, kind, exc", [
    ("ERR 4 BEAM_BROKEN", "beam_broken", BeamBroken),
    ("ERR 4 NO_TARGET", "not_found", TargetNotFound),
    ("ERR 4 UNSTABLE", "unstable", Unstable),
    ("ERR 4 TIMEOUT", "timeout", TrackerTimeout),
    ("ERR 4 NOT_INITIALISED", "error", TrackerError),
    ("ERR - UNKNOWN_COMMAND", "error", TrackerError),
])
def test_error_lines_map_to_kinds(line, kind, exc):
    c = codec()
    reply = c.parse_measure(line, 4)
    assert reply.kind == kind
    err = c.error(reply, "t")
    assert type(err) is exc and err.kind == kind and line in str(err)


def test_custom_error_patterns_first_match_wins():
    c = codec(errors={"not_found": r"^E;NOTGT", "beam_broken": [r"^E;BEAM", r"^EVT;LOST"]})
    assert c.parse_measure("E;BEAM;3").kind == "beam_broken"
    assert c.parse_measure("EVT;LOST").kind == "beam_broken"
    assert c.parse_measure("E;NOTGT").kind == "not_found"
    assert c.parse_measure("ERR 1 BEAM_BROKEN").kind == "garbage"   # the defaults are replaced, not merged


def test_garbage_is_reported_truncated_on_one_line():
    c = codec()
    line = c.decode(b"\xa7#%!?\x01" + b"x" * 200)
    reply = c.parse_measure(line, 1)
    assert reply.kind == "garbage"
    message = str(c.error(reply, "tracker"))
    assert isinstance(c.error(reply, "t"), GarbageReply)
    assert "\n" not in message and len(message) < 120 and message.endswith("...") and "#%!?" in message


def test_seq_mismatch_is_stale_for_replies_and_errors():
    c = codec()
    assert c.parse_measure("OK 3 1 2 3", seq=4).kind == "stale"
    assert c.parse_measure("ERR 3 BEAM_BROKEN", seq=4).kind == "stale"
    assert c.parse_measure("ERR 0003 BEAM_BROKEN", seq=3).kind == "beam_broken"   # compared as integers
    assert c.parse_measure("OK 3 1 2 3", seq=None).kind == "ok"                    # no seq in the request


def test_blank_and_ignored_lines():
    c = codec(ignore=[r"^EVT "])
    assert c.parse_measure("", 1).kind == "ignore"
    assert c.parse_measure("EVT WARMING_UP", 1).kind == "ignore"


def test_environment_groups_are_normalised():
    env = TrackerCodec.environment({"temp_f": "68", "pressure_inhg": "29.92", "humidity_pct": "40", "other": "1"})
    assert env == pytest.approx({"temp_c": 20.0, "pressure_hpa": 29.92 * 33.8639, "humidity_pct": 40.0})
    assert TrackerCodec.environment({"temp_k": "293.15", "pressure_kpa": "101.3"}) == \
        pytest.approx({"temp_c": 20.0, "pressure_hpa": 1013.0})


def test_measure_line_may_carry_environment_and_other_values():
    c = codec(measure="M", measure_regex=r"^(?P<x>{num});(?P<y>{num});(?P<z>{num});(?P<temp_c>{num});(?P<q>{num})$")
    xyz, extra = c.reading(c.parse_measure("1;2;3;21.5;0.9").groups)
    assert xyz == (1.0, 2.0, 3.0) and extra == {"temp_c": 21.5, "q": 0.9}


def test_non_finite_coordinates_are_rejected():
    c = codec()
    with pytest.raises(ValueError, match="non-finite"):
        c.reading(Reply("ok", "", {"x": "nan", "y": "1", "z": "1"}).groups)


def test_average_readings_mean_spread_and_unstable():
    readings = [TrackerReading((1.0, 0.0, 0.0), 0.0), TrackerReading((3.0, 0.0, 0.0), 1.0), (2.0, 0.0, 0.0)]
    mean, spread = average_readings(readings, stability_mm=1.5)
    assert mean == pytest.approx((2.0, 0.0, 0.0)) and spread == pytest.approx(1.0)
    with pytest.raises(Unstable, match="spread 1.0000 mm"):
        average_readings(readings, stability_mm=0.5)
    with pytest.raises(ValueError):
        average_readings([], 1.0)


@pytest.mark.parametrize("url, port, settings", [
    ("tracker+socket://10.0.0.5:5000", "socket://10.0.0.5:5000", {}),
    ("tracker+socket://localhost:5000?logging=debug", "socket://localhost:5000?logging=debug", {}),
    ("tracker+serial:///dev/ttyUSB0?baudrate=115200", "/dev/ttyUSB0", {"baudrate": 115200}),
    ("tracker+serial:///dev/ttyS1?baudrate=9600&parity=e&stopbits=2&rtscts=true", "/dev/ttyS1",
     {"baudrate": 9600, "parity": "E", "stopbits": 2, "rtscts": True}),
    ("tracker+serial://COM3?baudrate=19200", "COM3", {"baudrate": 19200}),
    ("tracker+rfc2217://moxa:4001?baudrate=115200", "rfc2217://moxa:4001", {"baudrate": 115200}),
    ("tracker+loop://", "loop://", {}),
])
def test_url_mapping(url, port, settings):
    spec = port_spec(url)
    assert spec.url == port and dict(spec.settings) == settings


@pytest.mark.parametrize("url", ["tracker+socket://host", "tracker+serial://", "socket://h:1", "tracker+usb://x",
                                 "tracker+serial:///dev/ttyS0?baudrate=fast", "tracker+serial:///dev/ttyS0?speed=1"])
def test_bad_urls_raise_value_error(url):
    with pytest.raises(ValueError, match="tracker"):
        open_tracker(url, {})


def test_serial_settings_in_url_and_options_must_not_conflict():
    assert dict(port_spec("tracker+serial:///dev/ttyS0", {"baudrate": 9600}).settings) == {"baudrate": 9600}
    with pytest.raises(ValueError, match="baudrate"):
        open_tracker("tracker+serial:///dev/ttyS0?baudrate=9600", {"serial": {"baudrate": 9600}})


@pytest.mark.parametrize("options, key", [
    ({"measure_cmd": "M"}, "measure_cmd"),
    ({"timeout_s": 0}, "timeout_s"),
    ({"timeout_s": "1"}, "timeout_s"),
    ({"retries": -1}, "retries"),
    ({"flush": "yes"}, "flush"),
    ({"length_unit": "cm"}, "length_unit"),
    ({"angle_unit": "mil"}, "angle_unit"),
    ({"encoding": "klingon"}, "encoding"),
    ({"measure_regex": "^OK (?P<x>"}, "measure_regex"),
    ({"measure_regex": r"^OK (?P<x>\S+) (?P<y>\S+)$"}, "measure_regex"),
    ({"measure": "M", "measure_regex": r"^(?P<r>\S+) (?P<hz>\S+) (?P<zen>\S+)$"}, "angle_unit"),
    ({"measure": "M", "measure_regex": r"^(?P<r>\S+) (?P<hz>\S+) (?P<zen>\S+)$", "angle_unit": "gon"},
     "azimuth_sense"),
    ({"measure": "M", "measure_regex": r"^(?P<r>\S+) (?P<az>\S+) (?P<zen>\S+)$", "vertical_zero": "horizon"},
     "vertical_zero"),
    ({"azimuth_sense": "cw"}, "azimuth_sense"),
    ({"coords": "polar"}, "coords"),
    ({"coords": "spherical"}, "measure_regex"),
    ({"measure": "MEAS {n}"}, "measure"),
    ({"measure": "MEAS"}, "measure"),                      # regex has a seq group, template has no {seq}
    ({"init": "INIT {"}, "init"),
    ({"init": 5}, "init"),
    ({"errors": {"fire": "^FIRE"}}, "errors"),
    ({"errors": {"beam_broken": "(("}}, "errors.beam_broken"),
    ({"errors": ["^ERR"]}, "errors"),
    ({"ignore": "^EVT"}, "ignore"),
    ({"environment_regex": None}, "environment_regex"),
    ({"serial": {"baud": 9600}}, "serial.baud"),
    ({"sensor_regex": "^T (?P<temp_c>{num})$"}, "sensor_regex"),
    ({"sensor_url": "tracker+loop://"}, "sensor_regex"),
    ({"sensor_url": "/dev/ttyUSB1", "sensor_regex": "^T"}, "sensor_url"),
    ({"sensor_url": "tracker+loop://", "sensor_regex": "^T (?P<temp_c>{num})$"}, "sensor_prefix"),
])
def test_bad_options_raise_one_line_value_error_naming_the_option(options, key):
    with pytest.raises(ValueError) as info:
        open_tracker("tracker+loop://", options)
    message = str(info.value)
    assert f"'{key}'" in message and "\n" not in message


def test_options_must_be_a_mapping():
    with pytest.raises(ValueError, match="mapping"):
        LineProfile.from_options(["MEAS"])
