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
  is the ``to_dict()`` of a :class:`campaign.records.PointRecord` (robot
  measurement) or :class:`campaign.records.NestRecord` (reference nest);
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

import json
import os
import signal
import threading
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.redact import redact

from .fsutil import fsync_dir, remove_quietly

from campaign.errors import DataError

from .records import NestRecord, PointRecord, RecordError, point_from_dict

try:  # POSIX advisory locking; absent on Windows.
    import fcntl
except ImportError:  # pragma: no cover - non-POSIX
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "LOG_NAME",
    "KINDS",
    "EXIT_STATUSES",
    "RunLogError",
    "NestRecord",
    "RunLogExistsError",
    "LogContents",
    "RunLog",
    "encode_record",
    "read_log",
    "completed_point_ids",
]

LOG_NAME = "log.jsonl"
KINDS = ("start", "point", "event", "stop")
EXIT_STATUSES = ("success", "abort", "fail", "paused")
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

    def records(self, n_joints: int | None = None) -> list[PointRecord | NestRecord]:
        """The point records as typed records (``n_joints`` joint values each, when known); a bad one raises
        :class:`RunLogError` naming its line and field."""
        out = []
        for k, data in enumerate(self.points):
            try:
                out.append(point_from_dict(data, n_joints))
            except RecordError as exc:
                line = self.point_lines[k] if k < len(self.point_lines) else None
                raise RunLogError(self.path, f"point record {data.get('point_id')!r}: {exc.message}",
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
    ``drivers.redact.redact``) so that a reader re-serialising the parsed
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
    except ValueError as exc:
        return None, f"not valid JSON ({exc.msg})"
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


def _parse_log(blob: bytes, path: str) -> LogContents:
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
    return _parse_log(p.read_bytes(), str(p))


def completed_point_ids(contents: LogContents) -> set[str]:
    """``point_id`` of every ``point`` record in the log (plan and check)."""
    return {str(d["point_id"]) for d in contents.points if "point_id" in d}


# --------------------------------------------------------------------------
# low-level file helpers


def _write_all(fd: int, payload: bytes) -> None:
    """``os.write`` the whole payload (one call unless the kernel writes short)."""
    view = memoryview(payload)
    while view:
        n = os.write(fd, view)
        if n <= 0:  # pragma: no cover - defensive
            raise OSError("os.write wrote nothing")
        view = view[n:]


@contextmanager
def _signals_deferred():
    """Block SIGINT, SIGTERM and SIGHUP in this thread for the duration (main thread, POSIX); a signal that
    arrives meanwhile is delivered when the block ends, so its handler never interrupts a record half-written
    or half-counted."""
    sigs = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _lock(fd: int, path: Path) -> None:
    """Take an exclusive non-blocking flock on ``fd`` (no-op without fcntl)."""
    if fcntl is None:  # pragma: no cover
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise RunLogError(str(path), "log is in use by another process") from None


def _read_fd(fd: int) -> bytes:
    """All bytes of the file behind ``fd`` (positional reads, offset 0)."""
    size = os.fstat(fd).st_size
    chunks, pos = [], 0
    while pos < size:
        chunk = os.pread(fd, min(size - pos, 1 << 24), pos)
        if not chunk:
            break
        chunks.append(chunk)
        pos += len(chunk)
    return b"".join(chunks)


def _create_with_start(path: Path, first_line: bytes) -> None:
    """Make ``path`` appear atomically, already holding ``first_line``.

    Writes a private temporary file, fsyncs it and hard-links it into place
    (``link`` fails if ``path`` exists).  Falls back to ``O_EXCL`` create +
    write where hard links are unsupported.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            _write_all(fd, first_line)
            os.fsync(fd)
        finally:
            os.close(fd)
        try:
            os.link(tmp, path)
        except FileExistsError:
            raise RunLogExistsError(str(path), "run log already exists") from None
        except OSError:  # no hard links here (e.g. FAT, some network mounts)
            _create_exclusive(path, first_line)
    finally:
        remove_quietly(tmp)


def _create_exclusive(path: Path, first_line: bytes) -> None:
    """Fallback create: ``O_EXCL`` then write + fsync the start record."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
    except FileExistsError:
        raise RunLogExistsError(str(path), "run log already exists") from None
    try:
        _write_all(fd, first_line)
        os.fsync(fd)
    finally:
        os.close(fd)


# --------------------------------------------------------------------------
# writer


class RunLog:
    """Append-only writer of ``RUN_DIR/log.jsonl``; keeps the descriptor open.

    Use :meth:`create` for a new run and :meth:`open_for_resume` to continue
    one.  Every ``append_*`` returns only after the record is fsynced.  After
    a failed write the object refuses further appends (the partial bytes are
    truncated off when possible; otherwise a resume will drop them).

    As a context manager, leaving the block without :meth:`close` writes a
    ``stop`` record: ``success`` on normal exit, ``abort`` on
    ``KeyboardInterrupt``, ``fail`` (with the exception as reason) otherwise.
    """

    def __init__(self, path: Path, fd: int, next_seq: int, n_points: int, contents: LogContents):
        """Internal: use :meth:`create` or :meth:`open_for_resume`."""
        self.path = path
        self._fd: int | None = fd
        self._seq = next_seq
        self._n_points = n_points
        self._size = os.fstat(fd).st_size
        self._broken = False
        self._mutex = threading.Lock()
        #: What was in the log when it was opened (start data, earlier points...).
        self.contents = contents

    # ---- construction ---------------------------------------------------

    @classmethod
    def create(cls, run_dir: str | os.PathLike, start: dict) -> "RunLog":
        """Create ``run_dir/log.jsonl`` with its ``start`` record (seq 0).

        ``start`` should hold ``config_sha256``, ``plan_sha256``, ``config``,
        ``created_utc``, ``software_version`` and ``units``; it is stored as
        given.  Raises :class:`RunLogExistsError` if the log already exists.
        """
        if not isinstance(start, dict):
            raise TypeError("start must be a dict")
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            run_dir.mkdir(parents=True, exist_ok=True)
            fsync_dir(run_dir.resolve().parent)
        path = run_dir / LOG_NAME
        line = encode_record("start", 0, start)
        _create_with_start(path, line)
        fsync_dir(run_dir)
        fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        try:
            _lock(fd, path)
        except BaseException:
            os.close(fd)
            raise
        contents = _parse_log(line, str(path))
        return cls(path, fd, next_seq=1, n_points=0, contents=contents)

    @classmethod
    def open_for_resume(cls, run_dir: str | os.PathLike) -> "RunLog":
        """Reopen an existing log to continue the run.

        Validates the whole file; a torn tail is cut off with ``ftruncate``
        (earlier bytes are never touched); a corrupt earlier record raises
        :class:`RunLogError`.  Appends an ``event`` record
        ``{"type": "resume", "previous_exit": <last stop status or None>,
        "dropped_tail_bytes": <int>}``.  ``self.contents`` holds what was read.
        """
        path = Path(run_dir) / LOG_NAME
        fd = os.open(path, os.O_RDWR | os.O_APPEND)
        try:
            _lock(fd, path)
            blob = _read_fd(fd)
            contents = _parse_log(blob, str(path))
            dropped = len(blob) - contents.n_good_bytes
            if dropped:
                os.ftruncate(fd, contents.n_good_bytes)
                os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        log = cls(path, fd, contents.n_records, len(contents.points), contents)
        previous = contents.stops[-1]["exit_status"] if contents.stops else None
        log.append_event(
            {"type": "resume", "previous_exit": previous, "dropped_tail_bytes": dropped}
        )
        return log

    # ---- appending ------------------------------------------------------

    @property
    def next_seq(self) -> int:
        """``seq`` the next record will get."""
        return self._seq

    @property
    def n_points(self) -> int:
        """Number of ``point`` records in the whole log (including earlier sessions)."""
        return self._n_points

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran (or the descriptor was lost)."""
        return self._fd is None

    def append_point(self, record: PointRecord | NestRecord | dict) -> int:
        """Durably append one measurement record; return its ``seq``.

        ``record`` is a :class:`PointRecord` or :class:`NestRecord` (stored as its ``to_dict()``), or a plain
        dict with a ``point_id`` (other writers and tools); numpy values are stored as lists/floats.
        NaN/inf are refused.
        """
        data = record.to_dict() if isinstance(record, (PointRecord, NestRecord)) else record
        if not isinstance(data, dict) or "point_id" not in data:
            raise TypeError("point data must be a record or a dict with a 'point_id'")
        seq = self._append("point", data)
        self._n_points += 1
        return seq

    def append_event(self, data: dict) -> int:
        """Durably append an event (``{"type": "pause"|"fault"|..., ...}``); return its seq."""
        if not isinstance(data, dict) or not isinstance(data.get("type"), str):
            raise TypeError("event data must be a dict with a string 'type'")
        return self._append("event", data)

    def close(self, exit_status: str = "success", reason: str = "") -> None:
        """Write the ``stop`` record and close the file; idempotent.

        ``exit_status`` is one of ``success``, ``abort``, ``fail``, ``paused``;
        ``n_points`` counts every point record in the log.
        """
        if exit_status not in EXIT_STATUSES:
            raise ValueError(f"exit_status must be one of {EXIT_STATUSES}, got {exit_status!r}")
        if self._fd is None:
            return
        try:
            if not self._broken:
                stop = {"exit_status": exit_status, "reason": str(reason), "n_points": self._n_points}
                self._append("stop", stop)
        finally:
            self._release()

    def _append(self, kind: str, data: dict) -> int:
        """Encode, write (one ``os.write``) and fsync one record."""
        with self._mutex:
            if self._fd is None or self._broken:
                raise RunLogError(str(self.path), "log is closed or broken; cannot append")
            try:
                line = encode_record(kind, self._seq, data)
            except (TypeError, ValueError) as exc:
                raise RunLogError(str(self.path), f"record not storable: {exc}") from None
            with _signals_deferred():          # Ctrl-C/SIGTERM/SIGHUP land after the record, never inside it
                try:
                    _write_all(self._fd, line)
                    os.fsync(self._fd)
                except BaseException:
                    self._recover()
                    raise
                self._size += len(line)
                seq = self._seq
                self._seq += 1
        return seq

    def _recover(self) -> None:
        """After a failed write: drop partial bytes if possible; refuse further appends."""
        self._broken = True
        try:
            os.ftruncate(self._fd, self._size)
            os.fsync(self._fd)
        except OSError:
            pass  # a resume will find and drop the torn tail

    def _release(self) -> None:
        """Close the descriptor (releases the flock)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)

    def __del__(self) -> None:
        # Dropped without close(): release the descriptor, write nothing (as a crash would).
        try:
            self._release()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass

    # ---- context manager ------------------------------------------------

    def __enter__(self) -> "RunLog":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._fd is None:
            return
        if exc_type is None:
            self.close("success", "")
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("abort", "interrupted")
        else:
            self.close("fail", f"{exc_type.__name__}: {exc}")

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"next_seq={self._seq}"
        return f"RunLog({str(self.path)!r}, {state})"
