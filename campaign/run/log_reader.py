"""Durable, append-only JSON-lines run log (``RUN_DIR/log.jsonl``).

Requirement: every measurement is on disk (written *and* fsynced) before the
robot is sent to the next point.  A process killed with SIGKILL at any moment
loses at most the record in flight and never alters earlier records; a torn
last record is detected and ignored on resume.

File format (one JSON object per line, bluesky event-model flavoured)::

    {"data":{...},"kind":"point","seq":7,"crc":"1a2b3c4d"}

* ``kind`` is ``start`` | ``point`` | ``event`` | ``stop``;
* ``seq`` is 0, 1, 2, ... consecutive over the whole file (across resumes);
  record 0 is the only ``start`` record;
* ``data`` is a JSON object (see the ``append_*`` methods); a ``point`` record's
  is the ``to_dict()`` of a :class:`campaign.run.log_records.PointRecord` (robot
  measurement) or :class:`campaign.run.log_records.NestRecord` (reference nest);
* ``crc`` is ``zlib.crc32`` of the canonical JSON of ``{"kind", "seq", "data"}``
  (``json.dumps(..., sort_keys=True, separators=(",", ":"), allow_nan=False)``)
  as 8 lowercase hex digits.

Durability: each record is one ``os.write`` of the full line (ending in
``"\\n"``) to a descriptor opened with ``O_APPEND``, followed by ``os.fsync``.
The file is created atomically with its start record already in it (written
to a temporary file, fsynced, hard-linked to ``log.jsonl``, directory
fsynced), so ``log.jsonl`` never exists without a complete start record.
The open log holds an exclusive ``flock`` so two controllers cannot append to
the same run.

Tail rule: a last line without ``"\\n"``, or a last line whose UTF-8, JSON,
structure or CRC is bad, is a *torn tail*: :func:`read_log` ignores it and
:meth:`RunLog.open_for_resume` removes it with ``ftruncate`` (only those bytes
go).  A bad record anywhere else, or a well-formed record with the wrong
``seq`` or ``kind`` order, is a hard :class:`RunLogError` naming the line.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import json
import os
from pathlib import Path
from typing import Any
import zlib

from campaign.errors import DataError
from campaign.io.json_fields import RecordError
from drivers.redaction import redact

from .log_events import ExitStatus
from .log_records import NestRecord, PointRecord, point_from_dict


__all__ = ["LOG_NAME", "KINDS", "EXIT_STATUSES", "RunLogError", "RunLogExistsError", "LogContents", "encode_record",
           "read_log", "completed_point_ids"]

LOG_NAME = "log.jsonl"
KINDS = ("start", "point", "event", "stop")
EXIT_STATUSES = tuple(s.value for s in ExitStatus)
_RECORD_KEYS = frozenset(("kind", "seq", "data", "crc"))
_HEX = frozenset("0123456789abcdef")


class RunLogError(DataError):
    """A run log is corrupt or misused; ``str()`` is ``"{path}: line {n}: {what}"``."""


class RunLogExistsError(RunLogError, FileExistsError):
    """:meth:`RunLog.create` found an existing log (also a ``FileExistsError``)."""


@dataclass
class LogContents:
    """Everything :func:`read_log` found in a log, in file order.

    ``start`` is the data of record 0; ``points``/``events``/``stops`` are the
    ``data`` dicts of those records as stored (:meth:`records` gives the points
    as typed, checked :class:`PointRecord`/:class:`NestRecord`; ``point_lines``
    their 1-based line numbers).  ``torn_tail`` is True when bytes after
    the last good record were ignored; ``n_good_bytes`` is the length of the
    intact prefix (the file size after a resume truncates the tail).
    ``n_records`` is the number of good records (= next ``seq``).
    """

    start: dict
    points: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    stops: list[dict] = field(default_factory=list)
    torn_tail: bool = False
    n_good_bytes: int = 0
    n_records: int = 0
    path: str = ""
    point_lines: list[int] = field(default_factory=list)

    def records(self, n_joints: int | None = None, foreign: bool = False) -> list[PointRecord | NestRecord]:
        """The point records as typed records (``n_joints`` joint values each, when known); a bad one raises
        :class:`RunLogError` naming its line and field. ``foreign``: read as points of any log (foreign shapes
        migrated, only the fields a dataset needs required: :func:`campaign.run.log_records.point_from_dict`);
        else as this software writes them."""
        out = []
        for k, data in enumerate(self.points):
            try:
                out.append(point_from_dict(data, n_joints, foreign))
            except RecordError as exc:
                line = self.point_lines[k] if k < len(self.point_lines) else None
                raise RunLogError(self.path or "<run log>", f"point record {data.get('point_id')!r}: {exc.message}",
                                  line=line) from None
        return out


# --------------------------------------------------------------------------
# encoding


def _json_default(obj: Any) -> Any:
    """JSON fallback: numpy arrays/scalars (anything with ``tolist``), paths."""
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def _canonical(kind: str, seq: int, data: Any) -> str:
    """Canonical JSON text of ``{"kind", "seq", "data"}`` (the CRC's input)."""
    return json.dumps(
        {"kind": kind, "seq": seq, "data": data},
        sort_keys=True,
        separators=(",", ":"),
        allow_nan=False,
    )


def _crc_hex(text: str) -> str:
    """CRC32 of ``text`` (UTF-8) as 8 lowercase hex digits."""
    return format(zlib.crc32(text.encode("utf-8")) & 0xFFFFFFFF, "08x")


def encode_record(kind: str, seq: int, data: dict) -> bytes:
    """The full line (bytes, ending in ``b"\\n"``) for one record.

    ``data`` is first normalised through a JSON round trip (numpy values to
    lists/floats, keys to strings; URL user-info and known secrets masked by
    ``drivers.redaction.redact``) so that a reader re-serialising the parsed
    record gets exactly the canonical text the CRC was computed on.
    Raises ``ValueError``/``TypeError`` for NaN/inf or unserialisable data.
    """
    first = redact(json.dumps(data, default=_json_default, allow_nan=False))
    canonical = _canonical(kind, seq, json.loads(first))
    # canonical is '{"data":...,"kind":...,"seq":N}'; append the crc key.
    line = f'{canonical[:-1]},"crc":"{_crc_hex(canonical)}"}}\n'
    return line.encode("utf-8")


# --------------------------------------------------------------------------
# decoding


def _decode_line(raw: bytes) -> tuple[dict | None, str]:
    """Parse one line (without ``"\\n"``); return (record, "") or (None, why)."""
    try:
        obj = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        return None, "not valid UTF-8"
    except ValueError as exc:           # JSONDecodeError, or an integer of more digits than Python converts
        return None, f"not valid JSON ({getattr(exc, 'msg', None) or 'a number too long to read'})"
    if not isinstance(obj, dict) or set(obj) != _RECORD_KEYS:
        return None, "not a record (expected keys kind, seq, data, crc)"
    kind, seq, data, crc = obj["kind"], obj["seq"], obj["data"], obj["crc"]
    if kind not in KINDS or not isinstance(data, dict):
        return None, f"bad kind {kind!r} or data not an object"
    if type(seq) is not int or seq < 0:
        return None, f"bad seq {seq!r}"
    if not isinstance(crc, str) or len(crc) != 8 or not set(crc) <= _HEX:
        return None, f"bad crc field {crc!r}"
    try:
        expected = _crc_hex(_canonical(kind, seq, data))
    except ValueError:
        return None, "data contains non-finite numbers"
    if crc != expected:
        return None, f"CRC mismatch (stored {crc}, computed {expected})"
    return obj, ""


def _check_order(rec: dict, expected_seq: int) -> str:
    """Logical checks on a well-formed record; return "" or the problem."""
    if rec["seq"] != expected_seq:
        return f"seq {rec['seq']} out of order (expected {expected_seq})"
    if (rec["kind"] == "start") != (expected_seq == 0):
        return "record 0 must be the only 'start' record"
    return ""


def parse_log(blob: bytes, path: str) -> LogContents:
    """Validate the bytes of a log file and sort its records (never writes)."""
    lines = blob.split(b"\n")
    fragment = lines.pop()  # b"" when the file ends with "\n"
    contents: LogContents | None = None
    offset = 0
    torn = bool(fragment)
    for index, raw in enumerate(lines):
        rec, why = _decode_line(raw)
        if rec is None:
            if index == len(lines) - 1 and not fragment:
                torn = True  # bad last line: the record in flight
                break
            raise RunLogError(path, why, line=index + 1)
        problem = _check_order(rec, index)
        if problem:
            raise RunLogError(path, problem, line=index + 1)
        if contents is None:
            contents = LogContents(start=rec["data"], path=path)
        else:
            _bucket(contents, rec)
            if rec["kind"] == "point":
                contents.point_lines.append(index + 1)
        offset += len(raw) + 1
    if contents is None:
        raise RunLogError(path, "no complete start record (log empty or torn)", line=1)
    contents.torn_tail = torn
    contents.n_good_bytes = offset
    contents.n_records = 1 + len(contents.points) + len(contents.events) + len(contents.stops)
    return contents


def _bucket(contents: LogContents, rec: dict) -> None:
    """Append a non-start record's data to the matching list of ``contents``."""
    {"point": contents.points, "event": contents.events, "stop": contents.stops}[
        rec["kind"]
    ].append(rec["data"])


def _log_path(path: str | os.PathLike) -> Path:
    """``path`` itself, or ``path/log.jsonl`` when ``path`` is a directory."""
    p = Path(path)
    return p / LOG_NAME if p.is_dir() else p


def read_log(path: str | os.PathLike) -> LogContents:
    """Read and validate a run log (file, or run directory); never writes.

    A torn tail is ignored (``torn_tail=True``).  Raises :class:`RunLogError`
    for a corrupt record before the last line, records out of ``seq`` order,
    or a missing start record; ``FileNotFoundError`` if there is no log.
    """
    p = _log_path(path)
    return parse_log(p.read_bytes(), str(p))


def completed_point_ids(contents: LogContents) -> set[str]:
    """``point_id`` of every ``point`` record in the log (plan, check and nest points), read as typed records of
    any log (``records(foreign=True)``; a bad record raises :class:`RunLogError`)."""
    return {rec.point_id for rec in contents.records(foreign=True)}
