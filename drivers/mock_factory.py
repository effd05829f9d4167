"""Registry entry points of the mock drivers: both need the shared ``world`` passed as context."""
from __future__ import annotations

from .base import DriverError
from .mock import MockRobot, MockTracker


def _world(url, context):
    world = context.get("world")
    if world is None:
        raise DriverError(f"{url}: mock drivers need a simulated cell (the config's simulation section)")
    return world


def robot(url, options, **context) -> MockRobot:
    return MockRobot(_world(url, context), url, float(options.get("speed_override_pct", 100.0)))


def tracker(url, options, **context) -> MockTracker:
    return MockTracker(_world(url, context), url, context.get("robot"))
