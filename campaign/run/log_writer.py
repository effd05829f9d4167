"""The durable log's writer: ``RunLog`` appends each record with one write + fsync under an exclusive lock; creation
is atomic and a resume cuts a torn tail (the format: ``campaign.run.log_reader``)."""
from __future__ import annotations

from contextlib import contextmanager
from datetime import datetime, timezone
try:  # POSIX advisory locking; absent on Windows.
    import fcntl
except ImportError:  # pragma: no cover - non-POSIX
    fcntl = None  # type: ignore[assignment]
import os
from pathlib import Path
import signal
import threading

from campaign.io.durable import create_new, fsync_dir, write_all

from .log_reader import EXIT_STATUSES, LOG_NAME, LogContents, RunLogError, RunLogExistsError, encode_record, parse_log
from .log_events import ExitStatus, LogEvent, ResumeEvent
from .log_records import NestRecord, PointRecord


# --------------------------------------------------------------------------
# low-level file helpers


def _finite_json(value):
    """``value`` (dicts, lists, tuples, scalars) with every non-finite float replaced by None."""
    if isinstance(value, float):
        return value if value == value and value not in (float("inf"), float("-inf")) else None
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_json(v) for v in value]
    return value


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
        try:
            create_new(path, line)      # appears atomically, already holding its start record
        except FileExistsError:
            raise RunLogExistsError(str(path), "run log already exists") from None
        fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        try:
            _lock(fd, path)
        except BaseException:
            os.close(fd)
            raise
        contents = parse_log(line, str(path))
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
            contents = parse_log(blob, str(path))
            dropped = len(blob) - contents.n_good_bytes
            if dropped:
                os.ftruncate(fd, contents.n_good_bytes)
                os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        log = cls(path, fd, contents.n_records, len(contents.points), contents)
        previous = contents.stops[-1]["exit_status"] if contents.stops else None
        log.append_event(ResumeEvent(previous, dropped))
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

    def append_event(self, event: LogEvent | dict) -> int:
        """Durably append an event (a :class:`campaign.run.log_events.LogEvent`, stored as its ``to_dict()``; or
        a plain dict with a string ``type``, other writers and tools); return its seq. An event is a note about the
        run, not a measurement: a non-finite float in it is stored as null, so a note can never stop the run (a
        point record with one is still refused)."""
        data = event.to_dict() if isinstance(event, LogEvent) else event
        if not isinstance(data, dict) or not isinstance(data.get("type"), str):
            raise TypeError("event data must be a dict with a string 'type'")
        return self._append("event", _finite_json(data))

    def close(self, exit_status: ExitStatus | str = ExitStatus.SUCCESS, reason: str = "") -> None:
        """Write the ``stop`` record and close the file; idempotent.

        ``exit_status`` is an :class:`ExitStatus` (or its value: ``success``, ``abort``, ``fail``, ``paused``);
        ``n_points`` counts every point record in the log; ``closed_utc`` is the wall-clock time (ISO 8601, UTC).
        """
        if exit_status not in EXIT_STATUSES:
            raise ValueError(f"exit_status must be one of {EXIT_STATUSES}, got {exit_status!r}")
        if self._fd is None:
            return
        try:
            if not self._broken:
                stop = {"exit_status": ExitStatus(exit_status).value, "reason": str(reason), "n_points": self._n_points,
                        "closed_utc": datetime.now(timezone.utc).isoformat()}
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
                    write_all(self._fd, line)
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
