"""Registry entry points of the mock drivers: they build their simulated world from the cell context.

The robot builds the world (``CellContext.simulation()``); a mock tracker opened with a mock robot shares that
robot's world, else it builds its own (and follows the real robot's joints)."""
from __future__ import annotations

from .base import DriverError
from .mock import MockRobot, MockTracker


def _world(url, context):
    world = context.get("world")                    # a world given directly (tests, tools)
    cell = context.get("cell")
    if world is None and cell is not None:
        robot = cell.robot
        world = robot.world if isinstance(robot, MockRobot) else (cell.simulation() if cell.simulation else None)
    if world is None:
        raise DriverError(f"{url}: mock drivers need a simulated cell (the config's simulation section)")
    return world


def robot(url, options, **context) -> MockRobot:
    return MockRobot(_world(url, context), url, float(options.get("speed_override_pct", 100.0)))


def tracker(url, options, **context) -> MockTracker:
    cell = context.get("cell")
    return MockTracker(_world(url, context), url, context.get("robot", cell.robot if cell is not None else None))


robot.uses_cell = tracker.uses_cell = True          # the registry passes them the whole CellContext


MOCK_OPTIONS = frozenset({"timeout_s"})     # the mock cell is configured by the simulation section, not options


def validate_options(url, options, **context) -> None:
    """Check ``options`` without building a driver: the mock drivers take none (``timeout_s`` is ignored)."""
    unknown = sorted(set(options or {}) - MOCK_OPTIONS)
    if unknown:
        raise DriverError(f"{url}: unknown option(s) {', '.join(map(str, unknown))}: mock drivers take no options "
                          "(the simulated cell is the config's simulation section)")
