"""Figures drawn once: a report's figures directory holds ``figures.json``, the index of its PNG files by section
(``calibration``, ``budget``, ``verify0``..., ``diagnosis``, ``iso9283``), each section under the key of what its
figures were drawn from: the section's documents and the drawing code (every source file of the ``campaign``
package, whose constants and wording the figures use, and the matplotlib version).

Writing a report again (``diagnose`` and ``verify`` rewrite the run's report, ``report --out`` copies it) takes a
section's figures from an index whose key is unchanged and whose PNG files are all intact (SHA-256 as indexed, regular
files, bounded sizes), and draws the others. A missing, damaged or foreign index only means drawing: it is never an
error. The index is written after the PNG files it lists, atomically.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

INDEX = "figures.json"
FORMAT = "campaign-figures/1"
MAX_INDEX_BYTES = 1 << 20           # an index lists a few dozen figures: a few kB
MAX_PNG_BYTES = 32 << 20            # a report figure is tens of kB


@dataclass(frozen=True)
class Section:
    """One section's figures as drawn (or reused) and the key of what they were drawn from."""
    key: str
    figures: tuple                  # html_figures.Figure, in page order


def _digest(h, obj) -> None:
    """Feed ``obj`` (documents: dicts, lists, scalars; numpy arrays; records' tuples) into the hash ``h``."""
    if isinstance(obj, dict):
        h.update(b"{")
        for k in sorted(obj, key=str):
            h.update(repr(str(k)).encode())
            _digest(h, obj[k])
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(b"[")
        for v in obj:
            _digest(h, v)
        h.update(b"]")
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"array{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())
    else:
        h.update(f"{type(obj).__name__}:{obj!r};".encode())


@lru_cache(maxsize=1)
def _code_key() -> str:
    """SHA-256 of the drawing code: every source file of the ``campaign`` package (~1 MB, a few ms) and the
    matplotlib version."""
    from importlib.metadata import version

    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256(version("matplotlib").encode())
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def section_key(name: str, *inputs) -> str:
    """The key of section ``name`` drawn from ``inputs`` (its documents and arrays) with this code."""
    h = hashlib.sha256(f"{FORMAT}:{_code_key()}:{name}".encode())
    _digest(h, inputs)
    return h.hexdigest()


def _bounded(path: Path, limit: int) -> bytes | None:
    """The bytes of the regular file ``path`` (never a link), or None when it is absent, special or too large."""
    try:
        if path.is_symlink() or not path.is_file():
            return None
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError:
        return None
    return data if len(data) <= limit else None


def same_file(path: Path, data: bytes) -> bool:
    """True when ``path`` is a regular file holding exactly ``data`` (it need not be written again)."""
    return _bounded(path, len(data)) == data


def read_index(directory: Path) -> dict:
    """{section: (key, [(name, title, caption, sha256)])} of ``directory``'s index; {} when it has none usable."""
    data = _bounded(Path(directory) / INDEX, MAX_INDEX_BYTES)
    try:
        doc = json.loads(data) if data is not None else {}
        if doc.get("format") != FORMAT:
            return {}
        return {str(name): (str(s["key"]), [(str(f["name"]), str(f["title"]), str(f["caption"]), str(f["sha256"]))
                                            for f in s["figures"]])
                for name, s in doc["sections"].items()}
    except (ValueError, TypeError, KeyError, AttributeError):
        return {}


def reused(directories, name: str, key: str) -> tuple | None:
    """The figures of section ``name`` drawn under ``key`` from the first of ``directories`` that indexes them with
    every PNG intact, as ``html_figures.Figure`` records; None when none does."""
    from .html_figures import Figure

    for d in directories:
        entry = read_index(d).get(name)
        if entry is None or entry[0] != key:
            continue
        figures = []
        for fname, title, caption, sha in entry[1]:
            png = _bounded(Path(d) / f"{fname}.png", MAX_PNG_BYTES)
            if png is None or hashlib.sha256(png).hexdigest() != sha:
                break
            figures.append(Figure(fname, title, caption, png))
        else:
            return tuple(figures)
    return None


def index_document(sections: dict[str, Section]) -> bytes:
    """``figures.json`` of the sections written (JSON bytes)."""
    doc = {"format": FORMAT, "sections": {
        name: {"key": s.key, "figures": [{"name": f.name, "title": f.title, "caption": f.caption,
                                          "sha256": hashlib.sha256(f.png).hexdigest()} for f in s.figures]}
        for name, s in sections.items()}}
    return (json.dumps(doc, indent=1) + "\n").encode()
