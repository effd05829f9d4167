"""Terminal-safe text: every string the controller shows goes through :class:`SafeConsole`.

Data strings (point and target ids, config names, file names, messages from devices) reach the terminal through
rich. A rich console would read ``[link=...]``/``[/]`` in them as markup, ``:smile:`` as emoji and pass escape
sequences (ESC, CSI, bidi overrides) straight to the terminal. :class:`SafeConsole` renders every string as plain
text: no markup, no emoji, control characters shown as ``\\x1b``-style escapes, URL user-info and known secrets
masked (:func:`drivers.redaction.redact`). Styling is done with ``style=`` and :class:`rich.text.Text`, never with
markup in strings. :class:`CleanLogRecords` applies the same to log records (console and ``campaign.log``).

Width: :func:`console_width` is the one rule (``--width N``, else ``COLUMNS``, else the terminal, else 100 columns
when nothing is a terminal); command output is word-wrapped at it and tables are fitted to it (:func:`keep_words`).
"""
from __future__ import annotations

import logging
import os
import re
import textwrap

from rich.console import Console, Group
from rich.table import Table
from rich.text import Text

from drivers.redaction import redact

# C0 controls except tab and newline, DEL, C1 controls, bidi embeddings/overrides/isolates, line/paragraph
# separators and the BOM/zero-width no-break space: anything that moves the cursor, changes the terminal's state
# or reorders what is shown
_CONTROL_RE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028-\u202e\u2066-\u2069\ufeff]")


def _escape(match: re.Match) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def clean(text: str) -> str:
    """``text`` safe to show: control characters escaped (``\\x1b``), URL user-info and secrets masked."""
    return redact(_CONTROL_RE.sub(_escape, text))


class SafeConsole(Console):
    """A rich console that shows every string as plain text (see module doc)."""

    def __init__(self, **kwargs) -> None:
        kwargs.update(markup=False, emoji=False)
        kwargs.setdefault("highlight", False)
        super().__init__(**kwargs)

    def render_str(self, text: str, **kwargs) -> Text:
        kwargs.update(markup=False, emoji=False)
        return super().render_str(clean(text), **kwargs)

    def print(self, *objects, **kwargs) -> None:
        """Strings wrap between words at the width, and a word longer than the width (a path) stays whole on its
        own line, where rich would fold it across lines (not with ``soft_wrap``: one line, any length)."""
        soft = kwargs.get("soft_wrap")
        if objects and all(isinstance(o, str) for o in objects) and not (self.soft_wrap if soft is None else soft):
            objects = (wrap_words(clean(kwargs.pop("sep", " ").join(objects)), self.width),)
            kwargs.update(overflow="ignore", crop=False)
        super().print(*objects, **kwargs)


def wrap_words(text: str, width: int, indent: str = "", hanging: str = "") -> str:
    """``text`` wrapped between words at ``width`` columns, each of its lines on its own; a word longer than the
    width stays whole. ``indent``/``hanging``: prefix of the first / the following lines of each."""
    return "\n".join(textwrap.fill(line, width, initial_indent=indent, subsequent_indent=hanging,
                                   break_long_words=False, break_on_hyphens=False) or line
                     for line in text.split("\n"))


PIPED_WIDTH = 100          # columns when no stream is a terminal and COLUMNS is not set
_width_option: int | None = None


def set_width(columns: int | None) -> None:
    """``--width N`` for every console of this command (None: the default rule of :func:`console_width`)."""
    global _width_option
    _width_option = columns


def console_width() -> int:
    """Columns of command output: ``--width N``, else ``COLUMNS``, else the terminal's width (stdout, stderr or
    stdin, the first that is a terminal), else :data:`PIPED_WIDTH`."""
    if _width_option:
        return _width_option
    env = os.environ.get("COLUMNS", "")
    if env.isdigit() and int(env) > 0:
        return int(env)
    for fd in (1, 2, 0):
        try:
            columns = os.get_terminal_size(fd).columns
        except (OSError, ValueError):
            continue
        if columns > 0:
            return columns
    return PIPED_WIDTH


def stdout_console() -> SafeConsole:
    """The console of command output (stdout), word-wrapped at :func:`console_width`."""
    return SafeConsole(width=console_width())


def keep_words(table: Table, width: int) -> Table | Group:
    """Column widths that fit ``table`` in ``width`` columns without cutting a word: from each column's natural
    width, the widest column that is still wider than its longest word loses a column at a time (rich alone
    would cut ``uncorrec…`` or fold ``axis_coupl|ing``); a table whose words cannot fit stays wider. Returns
    ``table``, or its title above it when the title is wider than the table."""
    texts = [[(t.plain if isinstance(t, Text) else str(t)) for t in (c.header, *c.cells)] for c in table.columns]
    natural = [max(len(line) for t in ts for line in (t.splitlines() or [""])) for ts in texts]
    shortest = [max([1, *(len(w) for t in ts for w in t.split())]) for ts in texts]
    chrome = table._extra_width + sum(table._get_padding_width(i) for i in range(len(table.columns)))
    widths = list(natural)
    while sum(widths) > width - chrome:
        shrinkable = [i for i, w in enumerate(widths) if w > shortest[i]]
        if not shrinkable:
            break
        widths[max(shrinkable, key=lambda i: widths[i])] -= 1
    for column, w in zip(table.columns, widths):
        column.width = w
    if isinstance(table.title, str) and len(table.title) > sum(widths) + chrome:
        title, table.title = table.title, None          # wider than the table: above it, wrapped at the width
        return Group(Text(title, style="table.title", justify="left"), table)
    return table


def print_notes(console: Console, notes: list[str], first: int = 1) -> None:
    """Numbered notes below a table (``[1] ...``), wrapped between words at the console's width with a hanging
    indent; note ``i`` is numbered ``first + i``."""
    for i, note in enumerate(notes, first):
        mark = f"[{i}] "
        console.print(wrap_words(clean(note), console.width, mark, " " * len(mark)), markup=False, overflow="ignore",
                      crop=False, soft_wrap=True)


class _StderrConsole(SafeConsole):
    """Counts what is printed on stderr (a command prints one line there at most)."""

    def print(self, *objects, **kwargs) -> None:
        global _stderr_prints
        _stderr_prints += 1
        super().print(*objects, **kwargs)


_stderr_prints = 0


def stderr_console() -> SafeConsole:
    """The console of error and warning lines (stderr): an error stays one line, whatever its length."""
    return _StderrConsole(stderr=True, soft_wrap=True)


def stderr_prints() -> int:
    """How many times something was printed through :func:`stderr_console` in this process."""
    return _stderr_prints


class CleanLogRecords(logging.Filter):
    """A handler filter: the record's message rendered once and cleaned (:func:`clean`) before any output."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = clean(record.getMessage()), None
        return True
