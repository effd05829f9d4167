"""Line-protocol tracker codec: command bytes out, reply line -> ``Reply`` in (pure, unit-tested on strings).

Positions in mm in the tracker frame; angles converted to radians internally.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from .base import GarbageReply, TrackerError, TrackerReading, average_samples
from .line_profile import ANGLE_STD_GROUPS, ENV_GROUPS, ERROR_KINDS, LENGTH_STD_GROUPS, LineProfile, show



# ---------------------------------------------------------------------------------------------------------- codec

@dataclass(frozen=True)
class Reply:
    """One classified line: ``kind`` is ``ok``, ``ignore``, ``stale``, ``garbage`` or an error kind."""
    kind: str
    line: str
    groups: Mapping[str, str] = field(default_factory=dict)


class TrackerCodec:
    """Pure encode/parse of the configured line protocol (no I/O)."""

    def __init__(self, profile: LineProfile) -> None:
        self.profile = profile
        self.rx_terminator = profile.rx_terminator.encode(profile.encoding)

    def command(self, template: str, seq: int) -> bytes:
        """Bytes to send: the filled template plus the tx terminator (unless the template already ends with it)."""
        text = template.format(seq=seq)
        if not text.endswith(self.profile.tx_terminator):
            text += self.profile.tx_terminator
        return text.encode(self.profile.encoding)

    def decode(self, raw: bytes) -> str:
        """A received line (without terminator) as stripped text; undecodable bytes become U+FFFD."""
        return raw.decode(self.profile.encoding, errors="replace").strip()

    def classify(self, line: str, regex: re.Pattern[str] | None, seq: int | None) -> Reply:
        """Blank/ignored lines, then error patterns (first wins), then ``regex``; a mismatching ``seq`` is stale."""
        if not line or any(p.search(line) for p in self.profile.ignore):
            return Reply("ignore", line)
        for kind, pattern in self.profile.errors:
            m = pattern.search(line)
            if m:
                return self._checked(Reply(kind, line, match_groups(m)), seq)
        m = regex.search(line) if regex is not None else None
        return self._checked(Reply("ok", line, match_groups(m)), seq) if m else Reply("garbage", line)

    @staticmethod
    def _checked(reply: Reply, seq: int | None) -> Reply:
        echoed = reply.groups.get("seq")
        if seq is None or echoed is None:
            return reply
        try:
            return reply if int(echoed) == seq else Reply("stale", reply.line, reply.groups)
        except ValueError:
            return Reply("garbage", reply.line)

    def parse_measure(self, line: str, seq: int | None = None) -> Reply:
        return self.classify(line, self.profile.measure_regex, seq)

    def reading(self, groups: Mapping[str, str]) -> tuple[tuple[float, float, float], dict[str, float]]:
        """xyz (mm, tracker frame) and extras (device std in mm/deg, environment, other numeric groups).

        Raises ``ValueError`` if a coordinate is not a finite number.
        """
        values = {k: group_float(k, v) for k, v in groups.items() if v is not None and k != "seq"}
        xyz = self._xyz(values)
        return xyz, self._extra(values)

    def _xyz(self, v: Mapping[str, float]) -> tuple[float, float, float]:
        k = self.profile.length_to_mm
        if self.profile.coords == "cartesian":
            out = (v["x"] * k, v["y"] * k, v["z"] * k)
        else:
            out = spherical_to_xyz(v["r"] * k, self._azimuth(v), self._zenith(v))
        if not all(math.isfinite(c) for c in out):
            raise ValueError(f"non-finite coordinates {out}")
        return out

    def _azimuth(self, v: Mapping[str, float]) -> float:
        a = self.profile.angle_to_rad
        return v["az"] * a if "az" in v else self.profile.azimuth_sign * v["hz"] * a

    def _zenith(self, v: Mapping[str, float]) -> float:
        a = self.profile.angle_to_rad
        if "zen" in v:
            return v["zen"] * a
        return v["v"] * a if self.profile.vertical_zero == "zenith" else math.pi / 2 - v["v"] * a

    def _extra(self, v: Mapping[str, float]) -> dict[str, float]:
        skip = {"x", "y", "z", "r", "az", "hz", "zen", "v"}
        extra = self.environment(v)
        for name, value in v.items():
            if name in LENGTH_STD_GROUPS:
                extra[f"{name}_mm"] = value * self.profile.length_to_mm
            elif name in ANGLE_STD_GROUPS:
                extra[f"{name}_deg"] = math.degrees(value * self.profile.angle_to_rad)
            elif name not in skip and name not in ENV_GROUPS:
                extra[name] = value
        return extra

    @staticmethod
    def environment(values: Mapping[str, Any]) -> dict[str, float]:
        """Environment groups normalised to ``temp_c``, ``pressure_hpa``, ``humidity_pct``; other keys dropped."""
        out = {}
        for name, value in values.items():
            if name in ENV_GROUPS and value is not None:
                key, convert = ENV_GROUPS[name]
                out[key] = convert(group_float(name, value))
        return out

    def error(self, reply: Reply, where: str) -> TrackerError:
        """The exception for a classified error or garbage line (message: one line, device text truncated)."""
        if reply.kind == "garbage":
            return GarbageReply(f"{where}: unparseable reply {show(reply.line)}")
        return ERROR_KINDS[reply.kind](f"{where}: device reports {reply.kind}: {show(reply.line)}")


def match_groups(m: re.Match[str]) -> dict[str, str]:
    return {k: v for k, v in m.groupdict().items() if v is not None}


def group_float(name: str, text: Any) -> float:
    if isinstance(text, (int, float)):
        return float(text)
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"group {name!r} is not a number: {show(text)}") from None


def spherical_to_xyz(r: float, az_rad: float, zen_rad: float) -> tuple[float, float, float]:
    """x = r sin(zen) cos(az), y = r sin(zen) sin(az), z = r cos(zen); r and xyz in the same length unit."""
    s = math.sin(zen_rad)
    return (r * s * math.cos(az_rad), r * s * math.sin(az_rad), r * math.cos(zen_rad))


def average_readings(readings: Sequence[TrackerReading | Sequence[float]],
                     stability_mm: float) -> tuple[tuple[float, float, float], float]:
    """``drivers.base.average_samples`` with the mean as a plain xyz tuple (mm)."""
    mean, spread = average_samples(readings, stability_mm)
    return tuple(mean.tolist()), spread
