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

:meth:`Claim.take` creates the directory and writes the marker just before the first output is written.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from campaign.errors import DataError
from campaign.io.durable import write_json
from .log_reader import LOG_NAME

MARKER = ".campaign-owner.json"
FORMAT = "campaign-owner/1"
RUN = "run"
OVERWRITE_HINT = "give a new path, or --overwrite to write there anyway"


@dataclass(frozen=True)
class Claim:
    """A checked output directory: ``take()`` creates it (with parents) and writes its marker."""
    path: Path
    kind: str
    source: str | None = None

    def take(self) -> Path:
        """Create the directory if needed and mark it as ``kind``'s (re-checked: nothing may have moved in)."""
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise DataError(str(self.path), "exists and is not a directory") from None
        if read_marker(self.path) != _marker_fields(self.kind, self.source):
            write_json(self.path / MARKER, {"format": FORMAT, "kind": self.kind, "source": self.source,
                                            "created_utc": datetime.now(timezone.utc).isoformat()})
        return self.path


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


def check_dir(path: str | Path, kind: str, overwrite: bool = False, source: str | None = None,
              option: str = "--out") -> Claim:
    """Check that ``kind`` may write into ``path`` (see module doc); DataError (nothing written) otherwise."""
    path = Path(path)
    if not path.exists():
        if path.is_symlink():
            raise DataError(str(path), f"{option} is a dangling symbolic link")
        return Claim(path, kind, source)
    if not path.is_dir():
        raise DataError(str(path), f"{option} exists and is not a directory")
    try:
        entries = [p.name for p in path.iterdir()]
    except OSError as exc:
        raise DataError(str(path), f"{option} is not readable: {exc.strerror or exc}") from None
    if not entries:
        return Claim(path, kind, source)
    marker = read_marker(path)
    if is_run_dir(path) and kind != RUN:
        raise DataError(str(path), f"{option} is a run directory (another run's data): {kind} writes into a new "
                                   "directory and never replaces a run's model or report; give a new path")
    if is_run_dir(path):
        raise DataError(str(path), f"{option} is another run's directory (it has a run log): continue it with "
                                   "--resume, or give a new path")
    if marker == _marker_fields(kind, source):
        return Claim(path, kind, source)
    if overwrite:
        return Claim(path, kind, source)
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
    return path


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
    return path


def _few(names: list[str], limit: int = 3) -> str:
    shown = ", ".join(sorted(names)[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")
