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
from pathlib import Path

from rich.console import Console

from campaign.config import load_config
from campaign.errors import CampaignError, ConfigError, DataError
from drivers.base import DriverConfigError, DriverError

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


def _run_arguments(parser: argparse.ArgumentParser) -> None:
    _config_argument(parser)
    parser.add_argument("--out", metavar="RUN_DIR", type=Path, help="run directory (default: output.dir/NAME-TIMESTAMP)")
    parser.add_argument("--resume", metavar="RUN_DIR", type=Path, help="continue an interrupted or paused run")


@command("run", "measure the plan on the cell's robot and tracker, then calibrate and report", _run_arguments)
def cmd_run(args: argparse.Namespace) -> int:
    from campaign.pipeline import run_campaign
    from campaign.report import render_parameters, render_stages

    cfg = load_config(args.config)
    out = _stdout()
    result = run_campaign(cfg, args.out, args.resume, out)
    o = result.outcome
    if o.exit_status != "success":
        hint = f"; continue with: campaign run {args.config} --resume {result.run_dir}" if o.exit_status != "abort" else ""
        _stderr().print(f"run {o.exit_status}: {o.reason}{hint}", style="red", markup=False)
        return EXIT_INTERRUPTED if o.exit_status == "abort" else EXIT_FAILED
    render_stages(out, result.processed.report)
    render_parameters(out, result.processed.report)
    out.print(f"run directory {result.run_dir}: log.jsonl, data.csv (interchange), report.json, model.json",
              markup=False)
    return EXIT_OK


def _plan_arguments(parser: argparse.ArgumentParser) -> None:
    _config_argument(parser)
    parser.add_argument("--csv", metavar="FILE", type=Path, help="also write the plan as CSV")


@command("plan", "build the measurement plan and print a summary (dry run, nothing moves)", _plan_arguments)
def cmd_plan(args: argparse.Namespace) -> int:
    from campaign.cell import nominal_kinematics
    from campaign.plan import build_plan, write_plan_csv
    from campaign.report import render_plan

    cfg = load_config(args.config)
    plan = build_plan(cfg, nominal_kinematics(cfg))
    m = cfg.tracker.measurement
    render_plan(_stdout(), plan, plan.estimated_duration_s(cfg.robot.max_joint_speed_deg_s, m.settle_s, m.samples))
    if args.csv:
        write_plan_csv(plan, args.csv)
    return EXIT_OK


def _reprocess_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", metavar="RUN_DIR_OR_CSV", type=Path, help="a run directory or an interchange CSV")
    parser.add_argument("--config", required=True, help="campaign YAML of the cell (nominal model, noise, options)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="where report.json and model.json go")


@command("reprocess", "calibrate and report offline from a run directory or an interchange CSV", _reprocess_arguments)
def cmd_reprocess(args: argparse.Namespace) -> int:
    from campaign.pipeline import reprocess
    from campaign.report import render_parameters, render_stages

    cfg = load_config(args.config)
    if not args.source.exists():
        raise DataError(str(args.source), "no such file or run directory")
    processed = reprocess(args.source, cfg, args.out)
    out = _stdout()
    render_stages(out, processed.report)
    render_parameters(out, processed.report)
    out.print(f"wrote {args.out}/report.json and {args.out}/model.json", markup=False)
    return EXIT_OK


def _correct_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True, help="campaign YAML of the cell")
    parser.add_argument("--model", required=True, type=Path, help="model.json written by run or reprocess")
    parser.add_argument("--targets", required=True, type=Path,
                        help="CSV target_id,x,y,z[,qw,qx,qy,qz] in mm in the robot base frame (a path: one row per point)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="where the corrected targets go")


@command("correct", "correct Cartesian targets with a calibrated model and write controller files", _correct_arguments)
def cmd_correct(args: argparse.Namespace) -> int:
    from campaign.correction import correct_targets, read_targets_csv, write_corrected
    from campaign.plan import tool_rotation
    from campaign.process import load_model

    cfg = load_config(args.config)
    model = load_model(args.model)
    targets = read_targets_csv(args.targets, tool_rotation(cfg.plan.tool_direction))
    accepted, rejected = correct_targets(cfg, model, targets)
    paths = write_corrected(cfg, accepted, rejected, args.out)
    out = _stdout()
    res = [t.predicted_residual_mm for t in accepted]
    out.print(f"{len(accepted)} targets corrected (predicted residual max {max(res, default=0):.2e} mm), "
              f"{len(rejected)} rejected; wrote {', '.join(p.name for p in paths)} in {args.out}", markup=False)
    for r in rejected[:20]:
        out.print(f"  rejected {r.target_id}: {r.reason}", markup=False)
    return EXIT_OK


def _verify_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", type=Path, help="a finished run (with model.json)")


@command("verify", "measure the run's test points after correction (closed loop) and report before/after",
         _verify_arguments)
def cmd_verify(args: argparse.Namespace) -> int:
    from campaign.pipeline import verify
    from rich.table import Table

    result = verify(args.run_dir, _stdout())
    rep = result.report
    t = Table(title=f"Verification on {rep['n']} test points, mm (noise floor {rep['noise_floor_mm']:.3f} mm)")
    for col in ("stage", "max", "mean", "RMS", "RMS / floor"):
        t.add_column(col, justify="left" if col == "stage" else "right")
    for name, s in rep["stages"].items():
        t.add_row(name, f"{s['max_mm']:.3f}", f"{s['mean_mm']:.3f}", f"{s['rms_mm']:.3f}",
                  f"{s['rms_mm'] / rep['noise_floor_mm']:.2f}")
    _stdout().print(t)
    _stdout().print(f"wrote {result.out_dir}/verify.json and log.jsonl", markup=False)
    if result.exit_status != "success":
        _stderr().print(f"verify {result.exit_status}: {result.reason}", style="red", markup=False)
        return EXIT_FAILED
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
    except DriverConfigError as exc:
        return _fail(f"error: {exc}", EXIT_BAD_INPUT)
    except DriverError as exc:
        return _fail(f"error: {exc}", EXIT_FAILED)
    except KeyboardInterrupt:
        return _fail("interrupted", EXIT_INTERRUPTED)


def _fail(message: str, code: int) -> int:
    """Print one red line on stderr; return ``code``."""
    _stderr().print(" ".join(message.split()), style="red", markup=False)
    return code
import campaign.cli_diagnose  # noqa: E402,F401  (registers "diagnose")
