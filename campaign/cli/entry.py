"""The entry point: build the parser from the registered subcommands, run one, translate its errors.

Operator-facing errors are printed as one red line on stderr, never as a traceback:

* ``ConfigError`` / ``DataError`` / ``PlausibilityError`` -> exit 2 (same as a command-line usage error)
* any other ``CampaignError`` or ``DriverError`` (e.g. a lost connection) -> exit 1
* ``OSError`` -> one line with the path and the cause: exit 2 (unusable path) or 1 (system failure)
* Ctrl-C, SIGTERM, SIGHUP -> exit 130
* anything else -> crash report file named on one line, exit 3 (see :mod:`campaign.cli.boundary`)
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from campaign.cli.common import COMMANDS, EXIT_BAD_INPUT, stderr_console


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line usage error (``campaign run: error: ... (see campaign run --help)``), exit 2."""

    def error(self, message: str):
        _fail(f"{self.prog}: error: {message} (see {self.prog} --help)", EXIT_BAD_INPUT)
        raise SystemExit(EXIT_BAD_INPUT)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    from campaign.cli import commands, diagnose, importing, report  # noqa: F401  (registration order = help order)
    from campaign.run.traceability import software_version

    parser = _Parser(
        prog="campaign",
        description="Industrial-robot accuracy campaigns with a laser tracker.",
    )
    parser.add_argument("--version", action="version", version=f"campaign {software_version()}",
                        help="print the version of the campaign software and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for cmd in COMMANDS.values():
        child = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        cmd.configure(child)
        child.set_defaults(func=cmd.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI and return the process exit code (console scripts pass it to ``sys.exit``)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    from campaign.cli.boundary import guarded
    from campaign.io.terminal_text import set_width

    from campaign.run.output_dirs import release_locks

    set_width(getattr(args, "width", None))          # --width N of the table commands (None: the terminal's)
    argv_text = list(argv) if argv is not None else sys.argv[1:]
    try:
        return guarded(lambda: args.func(args), argv_text, lambda: _run_dir_hint(args), _fail)
    finally:
        release_locks()                              # a command's directory locks end with it (also in-process)


def _run_dir_hint(args: argparse.Namespace) -> Path | None:
    """The run directory a crash report should go to, if the command names one written by campaign (never a
    directory of the user's: the report then goes to a temporary file)."""
    from campaign.run.log_reader import LOG_NAME
    from campaign.run.output_dirs import read_marker

    for name in ("resume", "run_dir", "out"):
        value = getattr(args, name, None)
        if isinstance(value, Path) and value.is_dir() and (read_marker(value) or (value / LOG_NAME).exists()):
            return value
    return None


def _fail(message: str, code: int) -> int:
    """Print one red line on stderr; return ``code``."""
    stderr_console().print(" ".join(message.split()), style="red", markup=False)
    return code
