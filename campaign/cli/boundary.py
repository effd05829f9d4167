"""The CLI's one error boundary: operator-facing errors as one line, anything else as a crash report.

* ``ConfigError`` / ``DataError`` / ``PlausibilityError`` -> exit 2 (bad input)
* ``OSError``: one line with the path and the cause; exit 2 when the path given is unusable (missing,
  not a directory, no permission, read-only file system), exit 1 when the system failed underneath a valid
  path (disk full, I/O error, quota)
* other ``CampaignError``, ``DriverError`` -> exit 1 (run or device failure)
* ``MemoryError`` -> exit 2 with one line (the data is too large for this machine; ``campaign.data.memory_check``
  refuses it before reading when it can tell)
* Ctrl-C, SIGTERM, SIGHUP -> exit 130 with one line, also when the signal arrives while the command finishes
  (the runner stops the robot and closes the log ``abort``; see :mod:`campaign.cli.signals`)
* anything else -> a crash report (traceback, versions, command) in the run directory or a temporary file,
  one line naming it, exit 3. A traceback never reaches the terminal.
* no error, but the calibration's verdict is FAIL against the config's ``acceptance`` bounds (``run``,
  ``reprocess``) -> exit 4, every output written (the commands decide it; it is not an error)
"""
from __future__ import annotations

import errno
import os
import sys
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path

from campaign.errors import CampaignError, ConfigError, DataError, PlausibilityError, Terminated, one_line

# The exit codes, one table for the CLI (campaign.cli.common re-exports them; README "Exit codes")
EXIT_OK = 0
EXIT_FAILED = 1                 # run failed or paused, or a system failure under a valid path
EXIT_BAD_INPUT = 2              # config, data, path, plausibility, identity
EXIT_CRASH = 3                  # internal error (crash report)
EXIT_ACCEPTANCE_FAIL = 4        # the outputs are written; the verdict against acceptance is FAIL
EXIT_INTERRUPTED = 130

# errno values meaning "the path you gave cannot be used" (input) rather than "the system failed" (run)
_INPUT_ERRNOS = frozenset({errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EACCES, errno.EPERM, errno.EROFS,
                           errno.ENAMETOOLONG, errno.ELOOP, errno.EEXIST, errno.ENOTEMPTY})


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
    if isinstance(exc, MemoryError):            # the early size check (campaign.data.memory_check) missed it
        return ("error: out of memory: the data needs more memory than this machine allows; calibrate a subset "
                "(`campaign select`) or use a machine with more memory"), EXIT_BAD_INPUT
    return None


def write_crash_report(exc: BaseException, argv: Sequence[str], run_dir: Path | None) -> Path:
    """Traceback, versions and command line in RUN_DIR/crash-TIMESTAMP.txt, else a temporary file; URL user-info
    and known secrets masked (:func:`drivers.redaction.redact`)."""
    import platform
    import tempfile
    import traceback

    from drivers.redaction import redact

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
    text = redact(text)
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


def guarded(run: Callable[[], int], argv: Sequence[str], run_dir_hint: Callable[[], Path | None],
            fail: Callable[[str, int], int]) -> int:
    """Call ``run()`` inside the boundary; ``fail(message, code)`` prints one line and returns ``code``.
    Signals are handled by :mod:`campaign.cli.signals` (installed here unless the process entry already did, and then
    restored here): any signal received while the command ran makes the exit code 130."""
    from . import signals

    own = signals.install()
    printed = stderr_prints()
    try:
        code = _guarded(run, argv, run_dir_hint, fail)
        if signals.received() is not None and code != EXIT_INTERRUPTED:   # dropped by a library, or arrived late
            code = (EXIT_INTERRUPTED if stderr_prints() > printed
                    else fail(_signal_line(signals.received()), EXIT_INTERRUPTED))
        return code
    finally:
        if own:
            signals.restore()


def _guarded(run, argv, run_dir_hint, fail) -> int:
    import warnings

    from . import signals

    try:
        try:
            with warnings.catch_warnings(record=True) as caught:
                errors = [f for f in warnings.filters if f[0] == "error"]     # -W error::X (the test suite) stays
                warnings.simplefilter("default")
                warnings.filters[:0] = errors
                code = run()
        finally:
            signals.disarm()                    # the exit code is being decided: a signal is recorded, not raised
        for text in (_unique_warnings(caught) if code in (EXIT_OK, EXIT_ACCEPTANCE_FAIL) else []):   # outputs written
            fail(f"warning: {text}", code)
        return code
    except BaseException as exc:  # noqa: BLE001 - this IS the boundary
        signals.disarm()
        if isinstance(exc, SystemExit):
            raise
        if signals.received() is not None:      # the signal's exception, or what a library made of it
            return fail(_signal_line(signals.received()), EXIT_INTERRUPTED)
        known = classify(exc)
        if known is not None:
            return fail(*known)
        try:
            report = write_crash_report(exc, argv, run_dir_hint())
        except Exception as inner:  # noqa: BLE001 - even the report failed: still one line
            return fail(f"internal error: {type(exc).__name__}: {exc} (crash report not written: {inner})",
                        EXIT_CRASH)
        return fail(f"internal error: {type(exc).__name__}: {_short(exc)}; crash report {report}", EXIT_CRASH)


def _signal_line(name: str) -> str:
    return "interrupted" if name == "SIGINT" else f"terminated by {name}"


def stderr_prints() -> int:
    """Lines printed on stderr so far through :mod:`campaign.io.terminal_text` (0 before it is loaded)."""
    terminal = sys.modules.get("campaign.io.terminal_text")
    return 0 if terminal is None else terminal.stderr_prints()


def run_process(main: Callable[[], int], line: Callable[[str], None]) -> None:
    """The console script: signals handled from the first instruction to the last (see :mod:`campaign.cli.signals`);
    ``main()`` runs the command; ``line(text)`` prints the one line of a signal that no one reported.
    Never returns: the process ends through :func:`campaign.cli.signals.exit_process`."""
    import importlib

    from . import signals

    # Before the handlers: C decimal (libmpdec) prints a warning on stderr when an import of it that a signal
    # interrupted is retried, and libraries import it while the command loads (seen once in 33 SIGTERMs of `report`).
    importlib.import_module("decimal")

    signals.install()
    code = EXIT_INTERRUPTED
    try:
        try:
            code = main()
        finally:
            signals.disarm()
    except KeyboardInterrupt:                   # while the CLI was loading or parsing its arguments
        pass
    except BaseException:
        if signals.received() is None:
            raise
        # The signal interrupted a library's import and the library re-raised it as its own error (numpy's C
        # modules: "ImportError: numpy._core.multiarray failed to import"): the signal's exit, not a crash.
    signals.exit_process(code, None if stderr_prints() else lambda name: line(_signal_line(name)))


def _short(exc: BaseException, limit: int = 160) -> str:
    text = one_line(exc)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _unique_warnings(caught, limit: int = 3) -> list[str]:
    """Python warnings raised during a command as short one-line texts (no file/line/source dump)."""
    from campaign.errors import DataWarning

    seen: list[str] = []
    for w in caught:
        message = one_line(w.message)
        text = message if issubclass(w.category, DataWarning) else f"{w.category.__name__}: {message}"
        if text not in seen:
            seen.append(text)
    return seen[:limit]
