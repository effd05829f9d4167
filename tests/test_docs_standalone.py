"""The project's docs stand alone: no reference to a file outside the repository."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md")])
ABSOLUTE = re.compile(r"(?<![\w.:/])/(?:work|home|mnt|srv)/[\w./-]*")
RELATIVE = re.compile(r"(?<![\w./])(?:\.\./)+[\w./-]*")
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


@pytest.mark.unit
@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_doc_references_stay_inside_the_repository(doc):
    text = doc.read_text(encoding="utf-8")
    bad = ABSOLUTE.findall(text)
    for r in RELATIVE.findall(text):
        path = (doc.parent / r.rstrip(".")).resolve()
        if ROOT not in path.parents or not path.exists():
            bad.append(r)
    for target in LINK.findall(text):
        if "://" in target or target.startswith("mailto:"):
            continue
        path = (doc.parent / target).resolve()
        if ROOT not in path.parents or not path.exists():
            bad.append(target)
    assert not bad, f"{doc.relative_to(ROOT)} refers outside the repository: {bad}"
