"""What every subcommand module shares: exit codes (the table is :mod:`campaign.cli.boundary`'s), the command
registry, consoles, plausibility lines.

:mod:`campaign.cli.entry` builds the parser from the registry; the subcommand modules (``commands``,
``diagnose``, ``report``) register into it. They import this module, never each other.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rich.console import Console

from campaign.cli.boundary import (EXIT_ACCEPTANCE_FAIL, EXIT_BAD_INPUT, EXIT_CRASH, EXIT_FAILED,  # noqa: F401
                                   EXIT_INTERRUPTED, EXIT_OK)                                      # (the one table)

if TYPE_CHECKING:                      # the calibration modules load when a command needs them
    from campaign.calibrate.plausibility import Plausibility

Handler = Callable[[argparse.Namespace], int]
Configure = Callable[[argparse.ArgumentParser], None]


@dataclass(frozen=True)
class Command:
    """A subcommand: its name, one-line help, argument setup and handler."""

    name: str
    help: str
    configure: Configure
    run: Handler


COMMANDS: dict[str, Command] = {}


def command(name: str, help: str, configure: Configure) -> Callable[[Handler], Handler]:
    """Decorator registering ``handler`` as subcommand ``name``."""

    def register(handler: Handler) -> Handler:
        COMMANDS[name] = Command(name, help, configure, handler)
        return handler

    return register


def stdout_console() -> Console:
    """The safe stdout console of campaign.io.terminal_text, imported on first use."""
    from campaign.io.terminal_text import stdout_console as safe_console
    return safe_console()


def stderr_console() -> Console:
    """The safe stderr console of campaign.io.terminal_text, imported on first use."""
    from campaign.io.terminal_text import stderr_console as safe_console
    return safe_console()


def overwrite_argument(parser: argparse.ArgumentParser) -> None:
    """``--overwrite``: write into an output path that exists and is not the command's own (never a run's)."""
    parser.add_argument("--overwrite", action="store_true",
                        help="write even where the output path exists with other files (an existing file, a "
                             "directory of other files or of another dataset's outputs); never into another run")


def _columns(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of columns, got {text!r}") from None
    if not 40 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"expected 40 to 1000 columns, got {text!r}")
    return value


def width_argument(parser: argparse.ArgumentParser) -> None:
    """``--width N``: the columns of the command's output (default: the terminal's, 100 when piped)."""
    parser.add_argument("--width", type=_columns, metavar="N",
                        help="output width in columns (default: the terminal's width, or COLUMNS; 100 when piped)")


def print_plausibility(out: Console, plaus: Plausibility | None) -> None:
    """The plausibility lines of a report: unit, nominal RMS vs bound, notes, overridden checks."""
    from campaign.calibrate.plausibility import plausibility_lines

    for line, style in plausibility_lines(plaus):
        out.print(line, style=style, markup=False)
