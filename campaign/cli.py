"""Command-line interface: ``campaign <command> ...``.

Subcommands register themselves with :func:`command`; each handler receives
the parsed ``argparse.Namespace`` and returns the exit code. Operator-facing
errors are printed as one red line on stderr, never as a traceback:

* ``ConfigError`` / ``DataError`` -> exit 2 (same as a command-line usage error)
* any other ``CampaignError`` (e.g. ``RunAborted``) -> exit 1
* Ctrl-C -> exit 130
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from rich.console import Console

from campaign.config import load_config
from campaign.errors import CampaignError, ConfigError, DataError

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130

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


def _stdout() -> Console:
    return Console(soft_wrap=True, highlight=False)


def _stderr() -> Console:
    return Console(stderr=True, soft_wrap=True, highlight=False)


# --------------------------------------------------------------------------- commands


def _config_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="campaign YAML file (see configs/irb2600.yaml)")


@command("validate", "check a campaign config file and print a summary", _config_argument)
def cmd_validate(args: argparse.Namespace) -> int:
    """Load and validate CONFIG; print a one-line summary."""
    cfg = load_config(args.config)
    _stdout().print(
        f"OK {cfg.source_path}: {cfg.name}: {cfg.robot.model}, {cfg.robot.n_joints} joints, "
        f"robot {cfg.robot.url}, tracker {cfg.tracker.url}",
        style="green",
        markup=False,
    )
    return EXIT_OK


# --------------------------------------------------------------------------- entry point


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="campaign",
        description="Industrial-robot accuracy campaigns with a laser tracker.",
    )
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
    try:
        return args.func(args)
    except (ConfigError, DataError) as exc:
        return _fail(f"error: {exc}", EXIT_BAD_INPUT)
    except CampaignError as exc:
        return _fail(f"error: {exc}", EXIT_FAILED)
    except KeyboardInterrupt:
        return _fail("interrupted", EXIT_INTERRUPTED)


def _fail(message: str, code: int) -> int:
    """Print one red line on stderr; return ``code``."""
    _stderr().print(" ".join(message.split()), style="red", markup=False)
    return code
