"""Durable file writes shared by the log, the reports and the write-back files."""
from __future__ import annotations

import glob
import json
import os
import re
import secrets
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from campaign.errors import DataError
from drivers.redaction import redact


def fsync_dir(directory: str | os.PathLike) -> None:
    """fsync a directory so a new entry in it survives a power cut (best effort where unsupported)."""
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - some filesystems refuse dir fsync
        pass
    finally:
        os.close(fd)


def remove_quietly(path: Path) -> None:
    """Remove a file of ours if it is there (a failure to do so never hides the error being handled)."""
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


TEMP_SUFFIX = ".tmp"
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)


def refuse_special(path: Path, what: str = "the output") -> None:
    """DataError unless ``path`` is absent or a regular file (not followed: a link, device node, FIFO, socket or
    directory there is never replaced, with or without --overwrite)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise DataError(str(path), f"{what} cannot be inspected: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        kind = ("a symbolic link" if stat.S_ISLNK(mode) else "a directory" if stat.S_ISDIR(mode) else
                "a device, FIFO or socket")
        raise DataError(str(path), f"{what} is {kind}, not a regular file: it is never replaced (not even with "
                                   "--overwrite); give the path of a regular file")


def create_temp(path: Path, mode: int = 0o666) -> tuple[int, Path]:
    """``(fd, name)`` of a new hidden temporary file beside ``path``, ``.NAME.PID.RANDOM.tmp``, created with
    ``O_EXCL | O_NOFOLLOW`` (a planted file or link of that name is never opened; a fresh name is drawn)."""
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(6)}{TEMP_SUFFIX}")
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, mode), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"{path.parent}: no free temporary name")   # pragma: no cover - 100 collisions


_TEMP_RE = re.compile(r"\.(?P<name>.+)\.(?P<pid>[0-9]+)(?:\.[0-9a-f]+)*\.tmp")


def stale_temp(entry: Path) -> bool:
    """True for a temporary file of ours left by a process that is gone (``.NAME.PID[.X].tmp``, a regular file of
    this user whose PID no longer runs): safe to remove, and no reason to call a directory foreign."""
    m = _TEMP_RE.fullmatch(entry.name)
    if m is None:
        return False
    try:
        st = os.lstat(entry)
    except OSError:
        return False
    if not stat.S_ISREG(st.st_mode) or st.st_uid != os.getuid():
        return False
    pid = int(m["pid"])
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except (PermissionError, OverflowError):
        return False
    return False


def remove_stale_temps(path: Path) -> None:
    """Remove the stale temporaries of ``path`` (:func:`stale_temp`) left beside it by killed writers."""
    try:
        entries = list(path.parent.glob(f".{glob.escape(path.name)}.*{TEMP_SUFFIX}"))
    except OSError:
        return
    for entry in entries:
        if stale_temp(entry):
            remove_quietly(entry)


def write_all(fd: int, data: bytes) -> None:
    """``os.write`` all of ``data`` to ``fd`` (one call unless the kernel writes short)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        if n <= 0:  # pragma: no cover - defensive
            raise OSError("os.write wrote nothing")
        view = view[n:]


def _fill(fd: int, data: bytes) -> None:
    """Write all of ``data`` to the new file ``fd``, fsync it and close it (closed on every path)."""
    try:
        write_all(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)


def create_new(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Make the new file ``path`` appear already holding ``data``, fsynced, never replacing anything: a temporary
    file (:func:`create_temp`) hard-linked into place, or where hard links are unsupported (FAT, some network
    mounts) an ``O_EXCL`` create, write and fsync. FileExistsError when ``path`` exists (another writer won); the
    temporary file is removed on every exit path (:func:`_removing_own_temps`); the directory is fsynced."""
    with _removing_own_temps(path):
        fd, tmp = create_temp(path, mode)
        try:
            _fill(fd, data)
            try:
                os.link(tmp, path)
            except FileExistsError:
                raise
            except OSError:
                _create_exclusive(path, data, mode)
        finally:
            remove_quietly(tmp)
    fsync_dir(path.parent)


@contextmanager
def _removing_own_temps(path: Path):
    """On any exception (a signal's too) remove every temporary of ``path`` this process made
    (``.NAME.PID.*.tmp``): also the one whose name a signal kept from reaching the caller, landing between the
    ``os.open`` that made it and the ``try`` that removes it."""
    try:
        yield
    except BaseException:
        try:
            own = list(path.parent.glob(f".{glob.escape(path.name)}.{os.getpid()}.*{TEMP_SUFFIX}"))
        except OSError:
            own = []
        for entry in own:
            remove_quietly(entry)
        raise


def _create_exclusive(path: Path, data: bytes, mode: int) -> None:
    """The fallback of :func:`create_new`: ``O_EXCL`` create, then write and fsync."""
    _fill(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, mode), data)


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: a new temporary file (:func:`create_temp`), fsync, os.replace,
    directory fsync. A reader sees the old file or the new one, never a mix; the temporary file is removed on
    every exit path (error, signal, a directory in the way); an existing ``path`` that is not a regular file is
    refused (:func:`refuse_special`); stale temporaries of ``path`` left by killed writers are removed."""
    path = Path(path)
    refuse_special(path)
    with _removing_own_temps(path):
        fd, tmp = create_temp(path)
        _fill(fd, data)
        refuse_special(path)                    # again: nothing may have been planted there meanwhile
        os.replace(tmp, path)
    fsync_dir(path.parent)
    remove_stale_temps(path)
    return path


def _plain(x: Any) -> Any:
    """numpy scalars and arrays as plain JSON values (``json.dumps`` default)."""
    if hasattr(x, "tolist"):                     # numpy arrays and scalars
        return x.tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def write_json(path: str | os.PathLike, data: Any) -> Path:
    """The one way the project writes a JSON file: atomically (see :func:`atomic_write`), NaN refused (missing
    figures are null), numpy values converted, URL user-info and known secrets masked (``drivers.redaction``)."""
    return atomic_write(path, redact(json.dumps(data, indent=1, allow_nan=False, default=_plain)).encode())
