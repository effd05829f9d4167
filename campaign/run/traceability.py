"""What identifies a measurement: hardware identity, driver and software versions, environment, run logging.

``device_identity`` goes into the log's start record, every ``devices`` event and ``report.json``;
``check_identity`` compares the robot and tracker models read at connect with ``robot.model`` / ``tracker.model``
of the config (a mismatch is a PlausibilityError before anything moves, ``--force`` records the override);
``environment_from_readings`` averages the environment values a tracker reports with its readings;
``run_logging`` sends Python ``logging`` (driver warnings included) to ``RUN_DIR/campaign.log`` and to the
console through rich.
"""
from __future__ import annotations

import logging
import logging.handlers
import re
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Iterator, Mapping, Sequence
from urllib.parse import urlsplit

from drivers.base import DriverError, Identifies, TrackerReading, Versioned, device_url

from campaign.errors import PlausibilityError, one_line
from campaign.io.terminal_text import CleanLogRecords

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
    if not isinstance(device, Identifies):
        return {k: "unknown" for k in keys} | {"note": "driver reports no identity"}
    try:
        got = dict(device.identity() or {})
    except DriverError as exc:
        log.warning("%s: identity not readable: %s", device_url(device, "device"), exc)
        return {k: "unknown" for k in keys} | {"note": f"identity not readable: {one_line(exc)}"}
    return {k: str(got.get(k, "unknown")) for k in keys} | {k: str(v) for k, v in got.items() if k not in keys}


def driver_versions(robot, tracker) -> dict[str, str]:
    """Driver classes with the software version, plus the installed protocol libraries' versions."""
    out = {"software": software_version()}
    for role, dev in (("robot", robot), ("tracker", tracker)):
        cls = type(dev)
        out[f"{role}_driver"] = f"{cls.__module__}.{cls.__qualname__}"
        extra = dev.driver_version if isinstance(dev, Versioned) else None
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
    """What identifies a run log's measurement (for report.json): the start record's hardware identity, versions,
    identity check and config/plan hashes; ``started_utc`` / ``finished_utc`` (start record, last stop record);
    ``measuring_s``, first move to last reading on the cell's clock (simulated time on a mock cell); and
    ``simulated_devices``, the roles ("robot", "tracker") whose driver URL is ``mock://``."""
    start = contents.start
    out = {k: start[k] for k in ("robot_identity", "tracker_identity", "driver_versions", "software_version",
                                 "identity_check", "config_sha256", "plan_sha256") if k in start}
    out["started_utc"] = start.get("created_utc")
    out["finished_utc"] = next((s["closed_utc"] for s in reversed(contents.stops) if "closed_utc" in s), None)
    t0 = [p["t_start_s"] for p in contents.points if isinstance(p.get("t_start_s"), (int, float))]
    t1 = [p["t_end_s"] for p in contents.points if isinstance(p.get("t_end_s"), (int, float))]
    out["measuring_s"] = float(max(t1) - min(t0)) if t0 and t1 else None
    out["simulated_devices"] = simulated_devices(start.get("config") or {})
    return out


def simulated_devices(config: Mapping) -> list[str]:
    """The roles ("robot", "tracker") of a config dict whose driver URL is a simulation (``mock://``)."""
    return [role for role in ("robot", "tracker")
            if urlsplit(str((config.get(role) or {}).get("url", ""))).scheme == "mock"]


def identity_changes(start: dict, now: dict) -> list[str]:
    """What differs between the hardware a run started with and the hardware now (resume): one line each."""
    out = []
    for role, keys in (("robot", ("controller_type", "serial", "software_version")),
                       ("tracker", ("model", "serial", "firmware"))):
        before, after = start.get(f"{role}_identity") or {}, now.get(f"{role}_identity") or {}
        out += [f"{role} {k} was {before[k]!r}, now {after.get(k)!r}" for k in keys
                if k in before and before[k] != after.get(k)]
    return out


# ------------------------------------------------------------------------------------------------ identity check
_MODEL_RE = re.compile(r"(?<![a-z0-9])([a-z]{1,6})[ -]?(\d{1,5})([a-z]{0,2})(?![a-z0-9])(?:[ -]*(\d[\d./]*))?")
_VENDOR_WORDS = frozenset({"abb", "kuka", "fanuc", "yaskawa", "motoman", "staubli", "kawasaki", "denso", "epson",
                           "universal", "robots", "robot", "leica", "faro", "api", "hexagon", "absolute", "tracker",
                           "laser", "emscon", "mock", "simulated", "series", "cb", "e"})


@dataclass(frozen=True)
class ModelName:
    """A model designation read from vendor text: ``family`` letters + number ("irb2600", "ur10", "at960"), an
    optional letter ``suffix`` ("e" of UR10e) and ``variant`` (payload/reach "12/1.65"); "" when not given."""
    family: str
    suffix: str = ""
    variant: str = ""


def model_name(text: str) -> ModelName | None:
    """The first model designation in ``text`` (vendor words skipped), None when the text names none
    ("simulated robot", "unknown")."""
    for m in _MODEL_RE.finditer(str(text).lower()):
        letters, number, suffix, variant = m.groups()
        if letters in _VENDOR_WORDS:
            continue
        return ModelName(letters + number, suffix, (variant or "").rstrip("./"))
    return None


def same_model(configured: str, reported: str) -> bool | None:
    """True when both texts name the same model (vendor formatting aside: "ABB IRB 2600-12/1.65" = "IRB2600";
    "Universal Robots UR10 (CB3)" = "UR10"), False when they name different ones (another family, or both give
    a different payload/reach variant or suffix), None when either names no model (nothing to compare)."""
    a, b = model_name(configured), model_name(reported)
    if a is None or b is None:
        return None
    if a.family != b.family:
        return False
    return not ((a.variant and b.variant and a.variant != b.variant) or (a.suffix and b.suffix and a.suffix != b.suffix))


def identity_check(cfg, identity: Mapping) -> dict:
    """Robot and tracker model read at connect vs ``robot.model`` / ``tracker.model``: per role ``configured``,
    ``reported``, ``serial``, ``result`` (match | mismatch | not compared) and, for a mismatch, ``reason``."""
    out = {}
    for role, section in (("robot", cfg.robot), ("tracker", cfg.tracker)):
        ident = identity.get(f"{role}_identity") or {}
        reported, serial = str(ident.get("model", "unknown")), str(ident.get("serial", "unknown"))
        same = same_model(section.model, reported)
        entry = {"configured": section.model, "reported": reported, "serial": serial,
                 "result": {True: "match", False: "mismatch", None: "not compared"}[same]}
        if same is False:
            entry["reason"] = (f"{role}.model is {section.model!r} but the {role} at {section.url} reports "
                               f"{reported!r} (serial {serial})")
        out[role] = entry
    return out


def check_identity(cfg, identity: Mapping, force: bool = False) -> dict:
    """``identity_check`` that raises PlausibilityError (exit 2; before anything moves) on a mismatch unless
    ``force``; forced, the result carries ``overridden`` (the reasons) for the log's start record and the report."""
    check = identity_check(cfg, identity)
    reasons = [e["reason"] for e in check.values() if e["result"] == "mismatch"]
    if reasons and not force:
        raise PlausibilityError(cfg.source_path, "; ".join(reasons) + ": not the configured cell; nothing moved")
    if reasons:
        log.warning("identity mismatch overridden with --force: %s", "; ".join(reasons))
        check["overridden"] = reasons
    return check
