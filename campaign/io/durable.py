"""Durable file writes shared by the log, the reports and the write-back files."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

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


def temp_name(path: Path) -> Path:
    """The hidden temporary name beside ``path`` used while it is written (``.NAME.PID.tmp``)."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: temp file, fsync, os.replace, directory fsync.
    A reader sees the old file or the new one, never a mix; the temporary file is removed on every exit path
    (error, signal, a directory in the way)."""
    path = Path(path)
    tmp = temp_name(path)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        remove_quietly(tmp)
        raise
    fsync_dir(path.parent)
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
