"""Output paths are owned: a command writes only into a directory that is new, empty, or its own.

Every directory a command creates carries a marker, ``.campaign-owner.json`` (``{"format": "campaign-owner/1",
"kind", "source", "created_utc"}``). Before anything is computed or moved, a command checks its outputs
(:func:`check_dir`, :func:`check_file`); nothing is written when the check fails (``DataError``: exit 2, one line):

* a new path, or an empty directory, is always fine;
* a directory whose marker has the command's ``kind`` (and, when the command has one, the same ``source``: the
  data it came from) is the command's own and is written again;
* anything else (foreign files, another command's or another dataset's outputs) is refused unless the user
  gives ``--overwrite``;
* a run directory (marker ``run``, or a ``log.jsonl``) is never written by another kind of command, even with
  ``--overwrite``: reprocessing or correcting writes a new directory and never replaces a run's model. Only the
  run's own additions (``report``, ``verify``, ``diagnose`` of that run, and an ``iso9283`` run made with its model
  in a new ``iso9283-TIMESTAMP`` subdirectory) go there, through :func:`check_campaign_dir`;
* an existing output *file* named by the user (``report --out FILE``, ``diagnose --json FILE``, ``export``,
  ``plan --csv``, ``select --out``, ``import --out``) is refused unless ``--overwrite``; one of a run directory's
  own files (its log, model, data) is refused even with ``--overwrite``: a run's files are its evidence.

:meth:`Claim.take` creates the directory and writes the marker just before the first output is written. The claim
holds under races: it takes the directory's lock (an flock on the directory, held until the process ends; a second
writer is refused with one line), checks the directory again under that lock (a writer that finished meanwhile, or
a file dropped there, is seen), and creates a new marker with ``O_EXCL``. A run holds the lock of its directory while
it measures, so ``report`` and ``diagnose`` never write into a live run (:func:`check_campaign_dir`). Stale
temporaries of killed writers (``campaign.io.durable.stale_temp``) never make a directory foreign.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from campaign.errors import DataError
from campaign.io.durable import create_new, refuse_special, remove_quietly, stale_temp, write_json
from .log_reader import LOG_NAME

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

MARKER = ".campaign-owner.json"
FORMAT = "campaign-owner/1"
RUN = "run"
OVERWRITE_HINT = "give a new path, or --overwrite to write there anyway"


@dataclass(frozen=True)
class Claim:
    """A checked output directory: ``take()`` creates it (with parents), locks it and writes its marker."""
    path: Path
    kind: str
    source: str | None = None
    overwrite: bool = False
    option: str = "--out"

    def take(self) -> Path:
        """Create the directory if needed, take its lock, check it again under the lock (nothing may have moved in
        since :func:`check_dir`) and mark it as ``kind``'s (a new marker with ``O_EXCL``)."""
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise DataError(str(self.path), f"{self.option} exists and is not a directory") from None
        hold_lock(self.path, self.option)
        check_dir(self.path, self.kind, self.overwrite, self.source, self.option)      # under the lock
        for entry in self.path.iterdir():
            if stale_temp(entry):
                remove_quietly(entry)
        marker = read_marker(self.path)
        if marker != _marker_fields(self.kind, self.source):
            doc = {"format": FORMAT, "kind": self.kind, "source": self.source,
                   "created_utc": datetime.now(timezone.utc).isoformat()}
            if marker is None and not (self.path / MARKER).exists():
                _create_marker(self.path / MARKER, doc)
            else:
                write_json(self.path / MARKER, doc)
        return self.path


_held: dict[str, int] = {}     # directory -> descriptor of its lock, held until the process ends


def hold_lock(directory: Path, option: str = "--out") -> None:
    """Take the lock of ``directory`` for the rest of this process (an exclusive flock on the directory itself);
    DataError when another process holds it (a run measuring there, or another command writing its outputs)."""
    key = str(Path(directory).resolve())
    if key in _held or fcntl is None:
        return
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0))
    except OSError as exc:
        raise DataError(str(directory), f"{option}: cannot open the directory: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise DataError(str(directory), f"{option} is in use by another campaign command right now (a run measuring, "
                                        "or another command writing there): wait for it to end, or give another "
                                        "path") from None
    _held[key] = fd


def release_locks() -> None:
    """Release every directory lock this process holds (the end of a command run in-process; a process that
    ends releases them anyway)."""
    while _held:
        _, fd = _held.popitem()
        try:
            os.close(fd)
        except OSError:
            pass


def _create_marker(path: Path, doc: dict) -> None:
    """A new marker (fails if one appeared meanwhile: :func:`campaign.io.durable.create_new`)."""
    try:
        create_new(path, json.dumps(doc, indent=1).encode(), 0o666)
    except FileExistsError:
        raise DataError(str(path.parent), "another campaign command marked this directory at the same moment: "
                                          "give another path") from None


def _marker_fields(kind: str, source: str | None) -> dict:
    return {"kind": kind, "source": source}


def read_marker(directory: Path) -> dict | None:
    """The ``kind`` and ``source`` of a directory's marker (None: no readable marker)."""
    try:
        doc = json.loads((Path(directory) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        return None
    return _marker_fields(doc.get("kind"), doc.get("source"))


def source_key(path: str | Path) -> str:
    """How a source (a run directory, a CSV file, a model) is named in a marker: its absolute path."""
    return str(Path(path).resolve())


def is_run_dir(directory: Path) -> bool:
    """A run's directory: marked ``run``, or holding a run log (runs written before markers existed)."""
    marker = read_marker(directory)
    return (marker is not None and marker["kind"] == RUN) or (Path(directory) / LOG_NAME).exists()


RUN_FILES = ("config.yaml", LOG_NAME, "model.json")
"""What a finished run's directory holds for the commands that go back to its cell (``verify``)."""


def check_finished_run(path: str | Path, command: str) -> Path:
    """``path`` as a finished run's directory (:data:`RUN_FILES`); else DataError (exit 2) saying what ``command``
    needs, and why another command's output directory (``reprocess``: no robot measured it) cannot serve."""
    directory = Path(path)
    needs = f"{command} needs a run directory with {', '.join(RUN_FILES)} (written by campaign run)"
    if not directory.is_dir():
        raise DataError(str(directory), f"no such run directory: {needs}")
    marker = read_marker(directory)
    if marker is not None and marker["kind"] != RUN:
        origin = f" from {marker['source']}" if marker["source"] else ""
        raise DataError(str(directory), f"written by campaign {marker['kind']}{origin}, not by a run: no robot "
                                        f"measured it, so it cannot be verified on the cell; {needs}")
    missing = [name for name in RUN_FILES if not (directory / name).is_file()]
    if missing:
        raise DataError(str(directory), f"not a finished run (no {', '.join(missing)}): {needs}")
    return directory


def not_started(directory: str | Path) -> bool:
    """A run's directory that holds no log yet (stopped between its marker and its first record): nothing was
    measured, so ``run --resume`` and ``run --overwrite`` start the run there again."""
    directory = Path(directory)
    marker = read_marker(directory) if directory.is_dir() else None
    return marker is not None and marker["kind"] == RUN and not (directory / LOG_NAME).exists()


def check_dir(path: str | Path, kind: str, overwrite: bool = False, source: str | None = None,
              option: str = "--out") -> Claim:
    """Check that ``kind`` may write into ``path`` (see module doc); DataError (nothing written) otherwise."""
    path = Path(path)
    claim = Claim(path, kind, source, overwrite, option)
    if path.is_symlink():
        raise DataError(str(path), f"{option} is a symbolic link: outputs never follow a link; give the directory "
                                   "it points to")
    if not path.exists():
        return claim
    if not path.is_dir():
        raise DataError(str(path), f"{option} exists and is not a directory")
    try:
        entries = [p.name for p in path.iterdir() if not stale_temp(p)]
    except OSError as exc:
        raise DataError(str(path), f"{option} is not readable: {exc.strerror or exc}") from None
    if not entries:
        return claim
    marker = read_marker(path)
    if is_run_dir(path) and kind != RUN:
        raise DataError(str(path), f"{option} is a run directory (another run's data): {kind} writes into a new "
                                   "directory and never replaces a run's model or report; give a new path")
    if is_run_dir(path) and (path / LOG_NAME).exists():
        raise DataError(str(path), f"{option} is another run's directory (it has a run log): continue it with "
                                   "--resume, or give a new path")
    if is_run_dir(path) and not overwrite:        # stopped before its log: nothing was measured
        raise DataError(str(path), f"{option} is a run that stopped before it measured anything (no {LOG_NAME}): "
                                   "continue it with --resume, or start it again with --overwrite")
    if marker == _marker_fields(kind, source) or overwrite:
        return claim
    what = (f"holds the outputs of another {marker['kind']}" + (f" (of {marker['source']})" if marker["source"]
                                                                 else "")
            if marker is not None else f"is not empty and was not written by campaign {kind} ({_few(entries)})")
    raise DataError(str(path), f"{option} {what}: {OVERWRITE_HINT}")


def check_campaign_dir(path: str | Path, what: str) -> Path:
    """A directory the command adds its own files to (``report``/``verify``/``diagnose`` of a run or of an output
    directory): it must carry a marker or a run log; DataError otherwise."""
    path = Path(path)
    if not path.is_dir():
        raise DataError(str(path), f"not a directory ({what})")
    if read_marker(path) is None and not (path / LOG_NAME).exists():
        raise DataError(str(path), f"not a directory written by campaign (no {MARKER} or {LOG_NAME}): {what} does "
                                   "not write into it; name the output file, or give --overwrite to write there anyway")
    live_check(path, what)
    return path


def live_check(path: Path, what: str) -> None:
    """Take the lock of a directory ``what`` adds its files to (held until this command ends, so no run resumes
    under it); DataError when a live campaign command holds it: nothing is written into a live run."""
    try:
        hold_lock(path, what)
    except DataError:
        raise DataError(str(path), f"is in use by a live campaign command (a run measuring, or another command "
                                   f"writing there): {what} does not write into it now; write elsewhere "
                                   "(--out/--html/--json FILE) or wait for it to end") from None


def check_file(path: str | Path, overwrite: bool = False, option: str = "--out", own: bool = False) -> Path:
    """An output file named by the user: its directory must exist; an existing file is refused unless
    ``overwrite``, and always when it is in a run directory (unless ``own``: the directory's own report, written
    again by ``report``); a directory in the way is always refused. DataError, nothing written."""
    path = Path(path)
    if path.is_dir():
        raise DataError(str(path), f"{option} is a directory, expected a file name")
    if not path.parent.is_dir():
        raise DataError(str(path), "the directory does not exist")
    if not own and (path.exists() or path.is_symlink()) and is_run_dir(path.resolve().parent):
        raise DataError(str(path), f"{option} is a file of a run directory (the run's evidence): it is never "
                                   "replaced, even with --overwrite; give a new path")
    if (path.exists() or path.is_symlink()) and not overwrite:
        raise DataError(str(path), f"{option}: the file exists: {OVERWRITE_HINT}")
    refuse_special(path, option)                    # --overwrite replaces a regular file only, never through a link
    return path


def _few(names: list[str], limit: int = 3) -> str:
    shown = ", ".join(sorted(names)[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")
