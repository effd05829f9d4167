"""Command-line interface: ``campaign <command> ...`` (``campaign.cli:main``, ``python -m campaign``).

:mod:`.common` holds the exit codes, the command registry and the consoles; :mod:`.commands`,
:mod:`.diagnose` and :mod:`.report` register subcommands into it (they import ``common``, never each
other); :mod:`.entry` builds the parser and translates errors into exit codes. All terminal rendering
lives in :mod:`campaign.report`.
"""
from __future__ import annotations

from campaign.cli import commands, diagnose, importing, report  # noqa: F401  (registration order = help order)
from campaign.cli.common import (COMMANDS, EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, Command,
                                 command)
from campaign.cli.entry import build_parser, main

__all__ = ["COMMANDS", "Command", "EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_OK", "build_parser",
           "command", "main"]
