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


MOCK_OPTIONS = frozenset({"timeout_s"})     # the mock cell is configured by the simulation section, not options


def validate_options(url, options, **context) -> None:
    """Check ``options`` without building a driver: the mock drivers take none (``timeout_s`` is ignored)."""
    unknown = sorted(set(options or {}) - MOCK_OPTIONS)
    if unknown:
        raise DriverError(f"{url}: unknown option(s) {', '.join(map(str, unknown))}: mock drivers take no options "
                          "(the simulated cell is the config's simulation section)")
