"""Choose drivers by URL: ``mock://``, ``abb-rws://host``, ``ur-rtde://host``, ``tracker+socket://host:port``, ``emscon://host``, ...

Real drivers are imported lazily so that a cell only needs the libraries of the drivers it uses.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping
from urllib.parse import urlsplit

from .base import DriverConfigError, DriverError, Robot, Tracker

# scheme -> "module:factory"; factories take (url, options, **context)
ROBOT_DRIVERS = {"mock": "drivers.mock_factory:robot", "abb-rws": "drivers.abb_rws:open_robot",
                 "ur-rtde": "drivers.ur:open_robot"}
TRACKER_DRIVERS = {"mock": "drivers.mock_factory:tracker", "tracker+socket": "drivers.line_tracker:open_tracker",
                   "tracker+serial": "drivers.line_tracker:open_tracker", "tracker+rfc2217": "drivers.line_tracker:open_tracker",
                   "tracker+loop": "drivers.line_tracker:open_tracker", "emscon": "drivers.emscon:open_tracker"}
ROBOT_SCHEMES = frozenset(ROBOT_DRIVERS)        # the url schemes a cell config may name (campaign.config.load)
TRACKER_SCHEMES = frozenset(TRACKER_DRIVERS)


def _factory(table: Mapping[str, str], url: str, what: str):
    scheme = urlsplit(url).scheme
    if scheme not in table:
        raise DriverError(f"{what} url {url!r}: unknown driver {scheme!r} (expected one of: {', '.join(sorted(table))})")
    module, name = table[scheme].split(":")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise DriverError(f"{what} url {url!r}: driver {scheme!r} is not available ({exc})") from exc


@dataclass(frozen=True)
class CellContext:
    """What the drivers of one cell may need beyond url and options: ``n_joints`` (robot config), ``simulation``
    (zero-argument builder of the simulated world behind mock:// drivers, called only by them), ``robot`` (the
    cell's robot, set when its tracker is opened). Real factories receive only what they use: robots
    ``n_joints``, trackers ``clock`` (the robot's ``simulated_clock`` if any); a factory with ``uses_cell``
    (the mock drivers) also receives the whole context as ``cell``."""
    n_joints: int | None = None
    simulation: Callable[[], Any] | None = None
    robot: Robot | None = None
    track_unit: str | None = None          # a track's mechanical unit (robot config), for controllers that move one


def _with_cell(factory, cell: CellContext, used: dict, context: dict) -> dict:
    used = {**used, **context}
    return {**used, "cell": cell} if getattr(factory, "uses_cell", False) else used


def open_robot(url: str, options: Mapping[str, Any] | None = None, cell: CellContext | None = None,
               **context) -> Robot:
    """Robot driver for ``url`` (not yet connected) in ``cell``; ``context``: further factory keywords (a test's
    ``transport`` or ``environ``)."""
    cell = cell or CellContext()
    factory = _factory(ROBOT_DRIVERS, url, "robot")
    used = {} if cell.n_joints is None else {"n_joints": cell.n_joints}
    if cell.track_unit is not None:
        used["track_unit"] = cell.track_unit
    return factory(url, dict(options or {}), **_with_cell(factory, cell, used, context))


def open_tracker(url: str, options: Mapping[str, Any] | None = None, cell: CellContext | None = None,
                 robot: Robot | None = None, **context) -> Tracker:
    """Tracker driver for ``url`` (not yet connected) in ``cell``, next to ``robot`` if given: readings are stamped
    with the robot's simulated clock when it has one. Bad options or url -> ``DriverConfigError``."""
    cell = replace(cell or CellContext(), robot=robot)
    factory = _factory(TRACKER_DRIVERS, url, "tracker")
    used = {"clock": getattr(robot, "simulated_clock", None)}
    try:
        return factory(url, dict(options or {}), **_with_cell(factory, cell, used, context))
    except ValueError as exc:                      # option validation of the line-protocol driver
        raise DriverConfigError(f"tracker url {url!r}: {exc}") from None


def check_options(kind: str, url: str, options: Mapping[str, Any] | None = None, **context) -> str | None:
    """Validate a driver's url and options as its factory would, without opening a connection.

    ``kind`` is ``robot`` or ``tracker``. Returns None when both are accepted, else ``"url: message"`` or
    ``"options: message"`` (which of the two the driver refused). The driver module declares the check as
    ``validate_options(url, options, **context)``; a driver without one is only checked for its scheme."""
    table = ROBOT_DRIVERS if kind == "robot" else TRACKER_DRIVERS
    scheme = urlsplit(url).scheme
    if scheme not in table:
        return f"url: unknown driver {scheme!r} (expected one of: {', '.join(sorted(table))})"
    module_name = table[scheme].split(":")[0]
    try:
        check = getattr(importlib.import_module(module_name), "validate_options", None)
    except ImportError as exc:
        return f"url: driver {scheme!r} is not available ({exc})"
    if check is None:
        return None
    for where, opts in (("url", {}), ("options", dict(options or {}))):
        try:
            check(url, opts, **context)
        except (DriverError, ValueError, TypeError) as exc:
            return f"{where}: {' '.join(str(exc).split())}"
    return None
