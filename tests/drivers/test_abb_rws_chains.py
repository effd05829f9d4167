"""The ABB RWS driver on chains other than 6R, checked on the wire against the RWS emulator (RWS 1.0 and 2.0) as the
six-axis path is: a seven-axis arm (YuMi: physical joint 3 is ABB's axis 7, ``eax_a`` of a jointtarget; the arm
angle in ``eax_a`` of a robtarget) and a 6-axis arm on a track (the carriage in ``eax_a``, read from the track's own
mechanical unit, which must be activated). abb_robot_client (an independent client) reads the same values."""
from __future__ import annotations

import pytest

from drivers import registry
from drivers.abb_axes import axes_layout
from drivers.abb_rws import validate_options
from drivers.base import DriverError, RobotNotReady
from drivers.emulators.rws_server import parse_literal
from tests.drivers.test_abb_rws import FAST, PASSWORD, USER, deadline, make_emu, version  # noqa: F401  (fixtures)

pytestmark = pytest.mark.system
UNUSED = 9e9


@pytest.fixture
def open_driver():
    robots = []

    def make(emu, **options):
        robot = registry.open_robot(emu.url, {**FAST, **options}, environ={"RWS_USER": USER, "RWS_PASSWORD": PASSWORD})
        robots.append(robot)
        robot.connect()
        return robot
    yield make
    for robot in robots:
        robot.close()


def test_seven_axis_jointtarget_and_arm_angle_on_the_wire(make_emu, open_driver, version):
    emu = make_emu(version, ext_q0=(0.0,))
    robot = open_driver(emu, n_joints=7)
    q = (10.0, -20.0, 35.5, 30.0, 40.0, 50.0, 60.0)             # physical order: joint 3 is ABB's axis 7
    robot.move_joints(q)
    target = parse_literal(emu.symbol("cal_target"))
    assert target[0] == [10, -20, 30, 40, 50, 60] and target[1] == [35.5] + [UNUSED] * 5
    assert emu.moves[-1][1] == (10, -20, 30, 40, 50, 60) and emu.ext[0] == 35.5
    assert robot.read_joints() == pytest.approx(q, abs=1e-4)
    assert parse_literal(emu.symbol("cal_reached"))[1][0] == pytest.approx(35.5)
    robot.move_linear((400.0, 100.0, 600.0), (0.0, 0.0, 1.0, 0.0), (0, -1, 0, 1), ext=(12.25,))
    ptarget = parse_literal(emu.symbol("cal_ptarget"))
    assert ptarget[3] == [12.25] + [UNUSED] * 5 and emu.robtarget_ext[0] == 12.25     # the arm angle, eax_a


def test_track_unit_on_the_wire(make_emu, open_driver, version):
    emu = make_emu(version, ext_q0=(0.0,), units=("TRACK_1",))
    robot = open_driver(emu, n_joints=7, track_unit="TRACK_1")
    q = (2500.5, 10.0, -20.0, 30.0, 40.0, 50.0, 60.0)            # the carriage (mm), then the arm (deg)
    robot.move_joints(q)
    assert parse_literal(emu.symbol("cal_target")) == [[10, -20, 30, 40, 50, 60], [2500.5] + [UNUSED] * 5]
    assert robot.read_joints() == pytest.approx(q, abs=1e-4)
    assert emu.count("GET", "/rw/motionsystem/mechunits/TRACK_1/jointtarget") >= 1    # read from its own unit
    assert emu.count("GET", "/rw/motionsystem/mechunits", "") >= 1


def test_track_unit_must_be_activated(make_emu, open_driver):
    emu = make_emu(1, ext_q0=(0.0,), units=("TRACK_1",))
    emu.units["TRACK_1"] = "Deactivated"
    with pytest.raises(RobotNotReady, match=r"mechanical unit TRACK_1 \(the track\) is deactivated.*ActUnit TRACK_1"):
        open_driver(emu, n_joints=7, track_unit="TRACK_1")
    emu2 = make_emu(1)
    with pytest.raises(RobotNotReady, match="TRACK_2 .* is missing"):
        open_driver(emu2, n_joints=7, track_unit="TRACK_2")


def test_abb_robot_client_reads_the_external_axes(make_emu, open_driver):
    """An independent client sees the seven-axis arm's axis 7 and arm angle where ABB puts them (eax_a)."""
    rws = pytest.importorskip("abb_robot_client.rws")
    emu = make_emu(1, ext_q0=(0.0,))
    robot = open_driver(emu, n_joints=7)
    robot.move_joints((1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0))
    robot.move_linear((400.0, 100.0, 600.0), (0.0, 0.0, 1.0, 0.0), (0, 0, 0, 0), ext=(-8.5,))
    client = rws.RWS(emu.base_url, USER, PASSWORD)
    joints = client.get_jointtarget("ROB_1")
    assert list(joints.robax) == [1, 2, 4, 5, 6, 7] and joints.extax[0] == 3
    assert client.get_robtarget().extax[0] == -8.5
    client.logout()


def test_layouts_and_refusals():
    assert axes_layout(7).split([1, 2, 3, 4, 5, 6, 7]) == ([1, 2, 4, 5, 6, 7], [3])
    assert axes_layout(7, track=True).join([1, 2, 3, 4, 5, 6], [900]) == (900, 1, 2, 3, 4, 5, 6)
    validate_options("abb-rws://10.0.0.1", {}, n_joints=7)
    validate_options("abb-rws://10.0.0.1", {}, n_joints=7, track_unit="TRACK_1")
    for context, words in (({"n_joints": 8}, "1 to 7 axes"), ({"n_joints": 6, "track_unit": "T"}, "plus the track")):
        with pytest.raises(DriverError, match=words):
            validate_options("abb-rws://10.0.0.1", {}, **context)
    assert registry.check_options("robot", "ur-rtde://10.0.0.5", {}, n_joints=7) == \
        "url: ur-rtde://10.0.0.5: a UR arm has 6 joints, the config has 7"
