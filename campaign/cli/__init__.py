"""Command-line interface: ``campaign <command> ...`` (``campaign.cli:main``, ``python -m campaign``).

:mod:`.common` holds the exit codes, the command registry and the consoles; :mod:`.commands`,
:mod:`.diagnose` and :mod:`.report` register subcommands into it (they import ``common``, never each
other); :mod:`.entry` builds the parser and translates errors into exit codes. All terminal rendering
lives in :mod:`campaign.report.terminal`.

This package module itself stays light: the console script calls :func:`main` without arguments, which installs
the signal handlers (:mod:`campaign.cli.signals`) before the rest of the CLI is imported. The other names are loaded
on first use.
"""
from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

__all__ = ["COMMANDS", "Command", "EXIT_ACCEPTANCE_FAIL", "EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_INTERRUPTED",
           "EXIT_OK", "build_parser", "command", "main"]
_LAZY = {"COMMANDS": "common", "Command": "common", "EXIT_ACCEPTANCE_FAIL": "common", "EXIT_BAD_INPUT": "common",
         "EXIT_FAILED": "common", "EXIT_INTERRUPTED": "common", "EXIT_OK": "common", "command": "common",
         "build_parser": "entry"}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``campaign ARGV`` and return its exit code. Without ``argv`` (the console script, ``python -m
    campaign``) run ``sys.argv`` as the whole process: signals are handled from the first instruction to the
    exit, and this call does not return (the process ends with the exit code)."""
    if argv is not None:
        from campaign.cli.entry import main as run
        return run(argv)
    from campaign.cli.boundary import run_process

    def run_argv() -> int:
        from campaign.cli.entry import main as run
        return run(sys.argv[1:])

    run_process(run_argv, _signal_line)
    raise AssertionError("unreachable: run_process ends the process")  # pragma: no cover


def _signal_line(text: str) -> None:
    from campaign.io.terminal_text import stderr_console
    stderr_console().print(text, style="red")


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f"campaign.cli.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'campaign.cli' has no attribute {name!r}")
