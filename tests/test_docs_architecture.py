"""docs/architecture.md is the code's own map: it names every module of campaign/, drivers/ and robocal/ (and no
module that is gone), and its picture of the rooms is the one the import statements draw.

``python -m tests.test_docs_architecture`` prints the picture as the code has it, to paste into the page."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.test_structure import CAMPAIGN_LAYERS, PACKAGES, ROBOCAL_LAYERS, ROOT, graph, product_graph, room_of

PAGE = ROOT / "docs" / "architecture.md"
NAMED = re.compile(r"`((?:campaign|drivers|robocal)/[\w/.]*)`")       # a path the page gives, in backticks
BEGIN, END = "<!-- rooms: drawn from the code by tests/test_docs_architecture.py -->", "<!-- end of rooms -->"


def module_paths(root: Path = ROOT) -> set[str]:
    """Every module file (``campaign/run/runner.py``) and every package (``campaign/run/``) of the product."""
    out = set()
    for pkg in PACKAGES:
        for path in (root / pkg).rglob("*.py"):
            rel = path.relative_to(root).as_posix()
            out.add(rel.removesuffix("__init__.py") if path.name == "__init__.py" else rel)
    return out


def named_paths(text: str) -> set[str]:
    return set(NAMED.findall(text))


def short(room: str) -> str:
    """``campaign.run`` -> ``run``; ``drivers.rapid`` -> ``drivers.rapid``."""
    return room.split(".", 1)[1] if room.split(".")[0] in ("campaign", "robocal") and "." in room else room


def picture(root: Path = ROOT) -> str:
    """Each room and the rooms its modules import, lowest first: campaign's and robocal's rooms in their order,
    drivers' own modules and sub-packages between them."""
    mods, edges = product_graph() if root == ROOT else graph(root)
    arrows: dict[str, set[str]] = {}
    for e in edges:
        src, dst = room_of(e.source), room_of(e.target)
        if src and dst and src != dst and not src.endswith("__main__"):
            arrows.setdefault(src, set()).add(dst)
    order = ([f"robocal.{r}" for r in ROBOCAL_LAYERS]
             + ["drivers"] + sorted(r for r in {room_of(m) for m in mods} if r and r.startswith("drivers."))
             + [f"campaign.{r}" for r in CAMPAIGN_LAYERS if r != "__main__"])
    rank = {r: i for i, r in enumerate(order)}
    lines = []
    for package, title in (("robocal", "robocal/"), ("drivers", "drivers/"), ("campaign", "campaign/")):
        lines.append(f"{title}")
        for room in (r for r in order if r.split(".")[0] == package):
            below = sorted(arrows.get(room, ()), key=lambda r: rank.get(r, -1))
            inside = [short(r) for r in below if r.split(".")[0] == package]
            other = [r for r in below if r.split(".")[0] != package]
            outside = []
            for pkg in ("drivers", "robocal"):
                names = [short(r) if pkg == "robocal" else r for r in other if r.split(".")[0] == pkg]
                if names:
                    outside.append(f"{pkg}: {' '.join(names)}" if pkg == "robocal" else " ".join(names))
            lines.append(f"  {short(room):<18} <- {' '.join(inside)}".rstrip(" <-"))
            if outside:
                lines.append(f"  {'':<18}    {'; '.join(outside)}")
    return "\n".join(lines)


def drawn(text: str) -> str:
    """The picture block of the page (between its markers, without the code fence)."""
    block = text.split(BEGIN, 1)[1].split(END, 1)[0]
    return "\n".join(line for line in block.strip().splitlines() if not line.startswith("```"))


@pytest.mark.unit
def test_architecture_page_names_every_module_and_nothing_gone():
    text = PAGE.read_text(encoding="utf-8")
    have, named = module_paths(), named_paths(text)
    missing = sorted(have - named)
    assert not missing, f"docs/architecture.md does not name: {missing}"
    gone = sorted(p for p in named if not (ROOT / p).exists())
    assert not gone, f"docs/architecture.md names what is not in the tree: {gone}"


@pytest.mark.unit
def test_architecture_picture_is_the_code_s():
    text = PAGE.read_text(encoding="utf-8")
    assert BEGIN in text and END in text, "docs/architecture.md has no rooms picture"
    assert drawn(text) == picture(), ("the rooms picture of docs/architecture.md is not the code's; "
                                      f"paste `python -m tests.test_docs_architecture`:\n{picture()}")


@pytest.mark.unit
def test_architecture_checks_fail_on_a_missing_or_gone_module(tmp_path):
    for rel in ("campaign/__init__.py", "campaign/run/__init__.py", "campaign/run/runner.py", "drivers/__init__.py",
                "robocal/__init__.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    assert module_paths(tmp_path) == {"campaign/", "campaign/run/", "campaign/run/runner.py", "drivers/", "robocal/"}
    assert named_paths("the runner (`campaign/run/runner.py`), `campaign/run/` and `robocal/kin.py`") == {
        "campaign/run/runner.py", "campaign/run/", "robocal/kin.py"}


if __name__ == "__main__":
    print(picture())
