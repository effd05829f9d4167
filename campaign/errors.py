"""Exceptions of the campaign controller.

Every error meant for the operator renders as exactly one line (no traceback):
the CLI prints ``str(error)`` and exits with a code chosen by the error class.
"""

from __future__ import annotations

__all__ = ["one_line", "CampaignError", "ConfigError", "DataError", "PlausibilityError", "DataWarning", "Terminated"]


def one_line(text: object) -> str:
    """``str(text)`` (an exception's message, a path, ...) with whitespace runs, newlines included, collapsed to
    single spaces: the one-line form every operator-facing message and log reason uses."""
    return " ".join(str(text).split())


class CampaignError(Exception):
    """Base class of every expected, operator-facing failure."""


class ConfigError(CampaignError, ValueError):
    """Invalid campaign configuration.

    ``str()`` is ``"{file}: {key_path}: {message}"``, e.g.
    ``configs/irb2600.yaml: plan.grid.step_mm: expected a positive number, got -200``.
    ``key_path`` is a dotted path with 0-based list indices
    (``robot.joints[2].a_mm``); it is ``""`` for errors about the whole file,
    in which case the middle part is left out.
    """

    def __init__(self, file: str, key_path: str, message: str) -> None:
        self.file = str(file)
        self.key_path = one_line(key_path)
        self.message = one_line(message)
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.key_path:
            return f"{self.file}: {self.key_path}: {self.message}"
        return f"{self.file}: {self.message}"

    def __reduce__(self):  # picklable despite the custom __init__
        return (type(self), (self.file, self.key_path, self.message))

    @classmethod
    def malformed_yaml(cls, file: str, line: int, column: int, problem: str) -> "ConfigError":
        """YAML syntax error at a 1-based ``line`` and ``column``."""
        return cls(file, f"line {line}, column {column}", f"malformed YAML: {problem}")


class DataError(CampaignError, ValueError):
    """Bad measurement/log input (CSV, JSONL, ...).

    ``str()`` is ``"{file}: line {line}, column {column}: {message}"``; the
    line and column parts are left out when unknown (``None``). ``column`` may
    be a 1-based number or a column name.
    """

    def __init__(
        self,
        file: str,
        message: str,
        line: int | None = None,
        column: int | str | None = None,
    ) -> None:
        self.file = str(file)
        self.message = one_line(message)
        self.line = line
        self.column = column
        super().__init__(str(self))

    def __str__(self) -> str:
        location = ", ".join(
            f"{label} {value}"
            for label, value in (("line", self.line), ("column", self.column))
            if value is not None
        )
        parts = [self.file, location, self.message] if location else [self.file, self.message]
        return ": ".join(parts)

    def __reduce__(self):
        return (type(self), (self.file, self.message, self.line, self.column))


class PlausibilityError(CampaignError):
    """The data do not fit the configured robot (wrong robot, wrong unit, impossible deltas): exit 2.

    ``str()`` is ``"{source}: {message} (override with --force)"``.
    """

    def __init__(self, source: str, message: str) -> None:
        self.source = str(source)
        self.message = one_line(message)
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"{self.source}: {self.message} (override with --force)"

    def __reduce__(self):
        return (type(self), (self.source, self.message))


class DataWarning(UserWarning):
    """Data accepted but implausible or incomplete (e.g. no test rows): one ``warning:`` line on stderr at the end of
    a successful command, and the same note in the report."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP received: handled like Ctrl-C (robot stopped, log closed ``abort`` with the reason)."""

    def __init__(self, signal_name: str) -> None:
        self.signal_name = signal_name
        super().__init__(signal_name)

    def __str__(self) -> str:
        return f"terminated by {self.signal_name}"
