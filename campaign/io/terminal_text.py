"""Terminal-safe text: every string the controller shows goes through :class:`SafeConsole`.

Data strings (point and target ids, config names, file names, messages from devices) reach the terminal through
rich. A rich console would read ``[link=...]``/``[/]`` in them as markup, ``:smile:`` as emoji and pass escape
sequences (ESC, CSI, bidi overrides) straight to the terminal. :class:`SafeConsole` renders every string as plain
text: no markup, no emoji, control characters shown as ``\\x1b``-style escapes, URL user-info and known secrets
masked (:func:`drivers.redact.redact`). Styling is done with ``style=`` and :class:`rich.text.Text`, never with
markup in strings. :class:`CleanLogRecords` applies the same to log records (console and ``campaign.log``).
"""
from __future__ import annotations

import logging
import re

from rich.console import Console
from rich.text import Text

from drivers.redact import redact

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


def stdout_console() -> SafeConsole:
    """The console of command output (stdout)."""
    return SafeConsole(soft_wrap=True)


class _StderrConsole(SafeConsole):
    """Counts what is printed on stderr (a command prints one line there at most)."""

    def print(self, *objects, **kwargs) -> None:
        global _stderr_prints
        _stderr_prints += 1
        super().print(*objects, **kwargs)


_stderr_prints = 0


def stderr_console() -> SafeConsole:
    """The console of error and warning lines (stderr)."""
    return _StderrConsole(stderr=True, soft_wrap=True)


def stderr_prints() -> int:
    """How many times something was printed through :func:`stderr_console` in this process."""
    return _stderr_prints


class CleanLogRecords(logging.Filter):
    """A handler filter: the record's message rendered once and cleaned (:func:`clean`) before any output."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = clean(record.getMessage()), None
        return True
