"""What identifies a measurement: hardware identity, driver and software versions, environment, run logging.

``device_identity`` goes into the log's start record, every ``devices`` event and ``report.json``;
``environment_from_readings`` averages the environment values a tracker reports with its readings;
``run_logging`` sends Python ``logging`` (driver warnings included) to ``RUN_DIR/campaign.log`` and to the
console through rich.
"""
from __future__ import annotations

import logging
import logging.handlers
from contextlib import contextmanager
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Iterator, Mapping, Sequence

from drivers.base import DriverError, TrackerReading

from .terminal import CleanLogRecords

ROBOT_KEYS = ("vendor", "model", "controller_type", "serial", "software_version")
TRACKER_KEYS = ("vendor", "model", "serial", "firmware")
ENV_KEYS = ("temp_c", "pressure_hpa", "humidity_pct")
LIBRARIES = ("ur_rtde", "httpx", "pyserial")     # third-party protocol libraries the drivers may use
LOGGERS = ("campaign", "drivers")
log = logging.getLogger(__name__)


def software_version() -> str:
    try:
        return version("robot-accuracy-campaign")
    except PackageNotFoundError:
        return "unknown"


def _identity(device, keys: Sequence[str]) -> dict[str, str]:
    """The device's ``identity()`` with every expected key ("unknown" where the driver cannot tell)."""
    read = getattr(device, "identity", None)
    if not callable(read):
        return {k: "unknown" for k in keys} | {"note": "driver reports no identity"}
    try:
        got = dict(read() or {})
    except DriverError as exc:
        log.warning("%s: identity not readable: %s", getattr(device, "url", "device"), exc)
        return {k: "unknown" for k in keys} | {"note": f"identity not readable: {' '.join(str(exc).split())}"}
    return {k: str(got.get(k, "unknown")) for k in keys} | {k: str(v) for k, v in got.items() if k not in keys}


def driver_versions(robot, tracker) -> dict[str, str]:
    """Driver classes with the software version, plus the installed protocol libraries' versions."""
    out = {"software": software_version()}
    for role, dev in (("robot", robot), ("tracker", tracker)):
        cls = type(dev)
        out[f"{role}_driver"] = f"{cls.__module__}.{cls.__qualname__}"
        extra = getattr(dev, "driver_version", None)
        if extra:
            out[f"{role}_driver_version"] = str(extra() if callable(extra) else extra)
    for lib in LIBRARIES:
        try:
            out[lib] = version(lib)
        except PackageNotFoundError:
            pass
    return out


def device_identity(robot, tracker) -> dict:
    """``robot_identity``, ``tracker_identity``, ``driver_versions`` and ``software_version`` of a cell."""
    return {"robot_identity": _identity(robot, ROBOT_KEYS), "tracker_identity": _identity(tracker, TRACKER_KEYS),
            "driver_versions": driver_versions(robot, tracker), "software_version": software_version()}


def environment_from_readings(readings: Sequence[TrackerReading]) -> dict[str, float]:
    """Mean of each environment value (temp_c, pressure_hpa, humidity_pct) the readings carry in ``extra``."""
    out = {}
    for key in ENV_KEYS:
        vals = [float(r.extra[key]) for r in readings if isinstance(r.extra, Mapping) and key in r.extra]
        if vals:
            out[key] = sum(vals) / len(vals)
    return out


class RunLogging:
    """Buffers log records until the run directory exists, then writes them to RUN_DIR/campaign.log."""

    def __init__(self, console=None, level: int = logging.INFO) -> None:
        self.buffer = logging.handlers.MemoryHandler(capacity=100000, flushLevel=logging.CRITICAL + 1)
        self.buffer.setLevel(level)
        self.buffer.addFilter(CleanLogRecords())          # control characters escaped, URL user-info masked
        self.file: logging.FileHandler | None = None
        self.console = None
        if console is not None:
            from rich.logging import RichHandler
            self.console = RichHandler(console=console, show_path=False, markup=False)
            self.console.setLevel(logging.WARNING)
            self.console.addFilter(CleanLogRecords())
        self.level = level
        self._saved: list[tuple[logging.Logger, int, bool]] = []

    def attach(self) -> None:
        for name in LOGGERS:
            lg = logging.getLogger(name)
            self._saved.append((lg, lg.level, lg.propagate))
            lg.setLevel(min(lg.level or self.level, self.level))
            lg.propagate = False                           # ours only: no duplicate on the root's handlers
            lg.addHandler(self.buffer)
            if self.console is not None:
                lg.addHandler(self.console)

    def to_file(self, run_dir: Path) -> Path:
        """Open RUN_DIR/campaign.log (appending on resume) and flush what was buffered into it."""
        path = Path(run_dir) / "campaign.log"
        self.file = logging.FileHandler(path, encoding="utf-8")
        self.file.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        self.file.setLevel(self.level)
        self.file.addFilter(CleanLogRecords())
        self.buffer.setTarget(self.file)
        self.buffer.flush()
        for lg, _, _ in self._saved:
            lg.removeHandler(self.buffer)
            lg.addHandler(self.file)
        return path

    def detach(self) -> None:
        for lg, level, propagate in self._saved:
            for h in (self.buffer, self.file, self.console):
                if h is not None:
                    lg.removeHandler(h)
            lg.setLevel(level)
            lg.propagate = propagate
        self._saved = []
        self.buffer.close()
        if self.file is not None:
            self.file.close()


@contextmanager
def run_logging(console=None) -> Iterator[RunLogging]:
    """``with run_logging(console) as rl: ...; rl.to_file(run_dir)``: logging for one command."""
    rl = RunLogging(console)
    rl.attach()
    try:
        yield rl
    finally:
        rl.detach()


def identification(contents) -> dict:
    """The identification fields of a run log's start record (for report.json)."""
    start = contents.start
    return {k: start[k] for k in ("robot_identity", "tracker_identity", "driver_versions", "software_version")
            if k in start}


def identity_changes(start: dict, now: dict) -> list[str]:
    """What differs between the hardware a run started with and the hardware now (resume): one line each."""
    out = []
    for role, keys in (("robot", ("controller_type", "serial", "software_version")),
                       ("tracker", ("model", "serial", "firmware"))):
        before, after = start.get(f"{role}_identity") or {}, now.get(f"{role}_identity") or {}
        out += [f"{role} {k} was {before[k]!r}, now {after.get(k)!r}" for k in keys
                if k in before and before[k] != after.get(k)]
    return out
