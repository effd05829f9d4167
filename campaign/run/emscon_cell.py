"""The emScon tracker emulator measuring a campaign config's simulated cell (a dry run of a real robot, or of the
emScon driver, against the cell the config simulates).

``python -m campaign.run.emscon_cell CONFIG [--robot-url URL] [--port PORT] [--print-port] [--faults ...]``: the
SMR stays at the plan's ``q_ref`` or, with ``--robot-url``, follows that robot's read-back joints; the other
options are those of ``python -m drivers.emulators.emscon_server``.
"""
from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

from drivers.emulators.emscon_server import PositionSource, parser, serve
from drivers.mock import MockTracker
from drivers.registry import CellContext, open_robot

from campaign.config.load import load_cell
from campaign.run.devices import mock_world


def cell_position_source(config_path: str, robot_url: str | None = None
                         ) -> tuple[PositionSource, Callable[[], None]]:
    """The SMR of the config's simulated cell (mm, tracker frame, with its per-point tracker error) and a close
    function; with ``robot_url`` the simulated robot follows that robot's read-back joints (the robot session is
    released by the close function), else it stays at the plan's q_ref."""
    cell = load_cell(config_path)
    cfg = cell.config
    world = mock_world(cell)
    world.faults = {}
    robot = None
    if robot_url:
        robot = open_robot(robot_url, cfg.robot.options, CellContext(n_joints=len(cfg.robot.joints)))
        robot.connect()
    follower = MockTracker(world, "mock://tracker", robot)

    def position() -> tuple[float, float, float]:
        if follower.robot is not None:
            follower.follow()
        return tuple(float(v) for v in world.p_smr_tracker_mm + world.point_error_mm)
    return position, (robot.close if robot is not None else (lambda: None))


def _parser() -> argparse.ArgumentParser:
    p = parser("python -m campaign.run.emscon_cell",
               "emScon emulator on 127.0.0.1 measuring a campaign config's simulated cell.")
    p.add_argument("config", help="campaign config whose simulated cell (mock world) is measured")
    p.add_argument("--robot-url", help="follow this robot's read-back joints (a driver URL)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    source, release = cell_position_source(args.config, args.robot_url)
    try:
        return serve(args, source)
    finally:
        release()


if __name__ == "__main__":
    sys.exit(main())
