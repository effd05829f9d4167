"""The CLI's one error boundary: operator-facing errors as one line, anything else as a crash report.

* ``ConfigError`` / ``DataError`` / ``PlausibilityError`` -> exit 2 (bad input)
* ``OSError``: one line with the path and the cause; exit 2 when the path given is unusable (missing,
  not a directory, no permission, read-only file system), exit 1 when the system failed underneath a valid
  path (disk full, I/O error, quota)
* other ``CampaignError``, ``DriverError`` -> exit 1 (run or device failure)
* Ctrl-C, SIGTERM, SIGHUP -> exit 130 (the runner stops the robot and closes the log ``abort``)
* anything else -> a crash report (traceback, versions, command) in the run directory or a temporary file,
  one line naming it, exit 3. A traceback never reaches the terminal.
"""
from __future__ import annotations

import errno
import os
import platform
import signal
import sys
import tempfile
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path

from .errors import CampaignError, ConfigError, DataError, PlausibilityError, Terminated

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_CRASH = 3
EXIT_INTERRUPTED = 130

# errno values meaning "the path you gave cannot be used" (input) rather than "the system failed" (run)
_INPUT_ERRNOS = frozenset({errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EACCES, errno.EPERM, errno.EROFS,
                           errno.ENAMETOOLONG, errno.ELOOP, errno.EEXIST, errno.ENOTEMPTY})
_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


def os_error_line(exc: OSError) -> tuple[str, int]:
    """One line ``error: PATH: cause`` and the exit code (2 unusable path, 1 system failure)."""
    where = exc.filename if exc.filename is not None else ""
    if exc.filename2 is not None:
        where = f"{where} -> {exc.filename2}"
    cause = exc.strerror or str(exc) or type(exc).__name__
    code = EXIT_BAD_INPUT if exc.errno in _INPUT_ERRNOS else EXIT_FAILED
    return (f"error: {where}: {cause}" if where else f"error: {cause}"), code


def classify(exc: BaseException) -> tuple[str, int] | None:
    """(one-line message, exit code) for an expected error, None for a crash."""
    from drivers.base import DriverConfigError, DriverError

    if isinstance(exc, (ConfigError, DataError, PlausibilityError, DriverConfigError)):
        return f"error: {exc}", EXIT_BAD_INPUT
    if isinstance(exc, (CampaignError, DriverError)):
        return f"error: {exc}", EXIT_FAILED
    if isinstance(exc, KeyboardInterrupt):
        return f"{exc if isinstance(exc, Terminated) else 'interrupted'}", EXIT_INTERRUPTED
    if isinstance(exc, OSError):
        return os_error_line(exc)
    return None


def write_crash_report(exc: BaseException, argv: Sequence[str], run_dir: Path | None) -> Path:
    """Traceback, versions and command line in RUN_DIR/crash-TIMESTAMP.txt, else a temporary file."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    text = "\n".join([
        f"campaign crash report {datetime.now(timezone.utc).isoformat()}",
        f"command: campaign {' '.join(argv)}",
        f"cwd: {os.getcwd()}",
        f"python: {sys.version.split()[0]} on {platform.platform()}",
        f"versions: {_versions()}",
        "",
        "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)),
    ])
    if run_dir is not None and run_dir.is_dir():
        try:
            path = run_dir / f"crash-{stamp}.txt"
            path.write_text(text, encoding="utf-8")
            return path
        except OSError:
            pass
    fd, name = tempfile.mkstemp(prefix=f"campaign-crash-{stamp}-", suffix=".txt")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    return Path(name)


def _versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for dist in ("robot-accuracy-campaign", "numpy", "scipy", "PyYAML", "rich"):
        try:
            out.append(f"{dist} {version(dist)}")
        except PackageNotFoundError:
            out.append(f"{dist} ?")
    return ", ".join(out)


@contextmanager
def signals_as_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP raise :class:`Terminated` (a KeyboardInterrupt) in the main thread, like Ctrl-C;
    the previous handlers are restored afterwards."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Terminated(signal.Signals(signum).name)

    previous = {}
    for sig in _SIGNALS:
        try:
            previous[sig] = signal.signal(sig, handler)
        except (OSError, ValueError):
            pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def guarded(run: Callable[[], int], argv: Sequence[str], run_dir_hint: Callable[[], Path | None],
            fail: Callable[[str, int], int]) -> int:
    """Call ``run()`` inside the boundary; ``fail(message, code)`` prints one line and returns ``code``."""
    import warnings

    try:
        with signals_as_interrupt(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            code = run()
        for text in (_unique_warnings(caught) if code == EXIT_OK else []):   # one line each, success only
            fail(f"warning: {text}", code)
        return code
    except BaseException as exc:  # noqa: BLE001 - this IS the boundary
        if isinstance(exc, SystemExit):
            raise
        known = classify(exc)
        if known is not None:
            return fail(*known)
        try:
            report = write_crash_report(exc, argv, run_dir_hint())
        except Exception as inner:  # noqa: BLE001 - even the report failed: still one line
            return fail(f"internal error: {type(exc).__name__}: {exc} (crash report not written: {inner})",
                        EXIT_CRASH)
        return fail(f"internal error: {type(exc).__name__}: {_short(exc)}; crash report {report}", EXIT_CRASH)


def _short(exc: BaseException, limit: int = 160) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _unique_warnings(caught, limit: int = 3) -> list[str]:
    """Python warnings raised during a command as short one-line texts (no file/line/source dump)."""
    seen: list[str] = []
    for w in caught:
        text = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
        if text not in seen:
            seen.append(text)
    return seen[:limit]
