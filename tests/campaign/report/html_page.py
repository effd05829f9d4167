"""A report.html read without a browser (stdlib ``html.parser``): the section ids in order, the visible text with
block and cell boundaries as line breaks (``<code>``, ``<style>`` left out), and every table as rows of cell texts.
Plus the generic checks of the page text the HTML tests share."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from html.parser import HTMLParser

BLOCK = {"p", "li", "ul", "dl", "dt", "dd", "h1", "h2", "h3", "section", "table", "tr", "td", "th", "figcaption",
         "figure", "div", "br", "body"}
SKIP = {"style", "script", "code", "title"}
JOIN = re.compile(r"[^\s.]\.[A-Z]")
"""Two sentences without a space between them (``0.0585 mm.The``): a period after a word, then a capital."""


@dataclass
class Page:
    sections: list[str] = field(default_factory=list)       # <section id> in document order
    text: str = ""                                          # visible text, block boundaries as "\n"
    tables: dict[str, list[list[str]]] = field(default_factory=dict)   # table id (or "table-N") -> rows of cells


class _Reader(HTMLParser):
    def __init__(self):
        super().__init__()
        self.page, self.out, self.skip = Page(), [], 0
        self.tables: list[tuple[str, list]] = []          # open tables (nested: the registration matrix)
        self.cell: list[str] | None = None
        self.n = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in SKIP:
            self.skip += 1
        if tag in BLOCK:
            self.out.append("\n")
            if self.cell is not None:
                self.cell.append(" ")
        if tag == "section" and a.get("id"):
            self.page.sections.append(a["id"])
        if tag == "table":
            self.n += 1
            self.tables.append((a.get("id") or f"table-{self.n}", []))
        elif tag == "tr" and self.tables:
            self.tables[-1][1].append([])
        elif tag in ("td", "th") and self.tables and self.tables[-1][1]:
            self.cell = []

    def handle_endtag(self, tag):
        if tag in SKIP:
            self.skip -= 1
        if tag in BLOCK:
            self.out.append("\n")
        if tag in ("td", "th") and self.cell is not None and self.tables:
            self.tables[-1][1][-1].append(" ".join("".join(self.cell).split()))
            self.cell = None
        elif tag == "table" and self.tables:
            name, rows = self.tables.pop()
            self.page.tables[name] = rows

    def handle_data(self, data):
        if self.skip:
            return
        self.out.append(data)
        if self.cell is not None:
            self.cell.append(data)


def read_page(html: str) -> Page:
    r = _Reader()
    r.feed(html)
    r.page.text = re.sub(r"[ \t]*\n\s*", "\n", "".join(r.out))
    return r.page


def sentence_joins(text: str) -> list[str]:
    """Every place where a sentence runs into the next without a space, with its context."""
    return [text[max(0, m.start() - 25):m.end() + 15] for m in JOIN.finditer(text)]


def empty_columns(rows: list[list[str]]) -> list[str]:
    """The header of every column whose cells below the header are all "-" (rows as wide as the header only)."""
    if len(rows) < 2:
        return []
    head, body = rows[0], [r for r in rows[1:] if len(r) == len(rows[0])]
    return [head[j] for j in range(len(head)) if body and all(r[j] == "-" for r in body)]
