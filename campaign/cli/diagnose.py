"""``campaign diagnose``: the sim-to-real gap of a dataset, or the withheld-effect self-check.

    campaign diagnose RUN_DIR_OR_CSV --config CONFIG [--json OUT.json] [--plots DIR] [--html FILE]
    campaign diagnose --self-check [--seeds N] [--json OUT.json]

Imported by :mod:`campaign.cli`, which registers it.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from campaign.cli.common import (EXIT_FAILED, EXIT_OK, stderr_console, stdout_console, command, overwrite_argument,
                                 width_argument)
from campaign.errors import DataError

MAX_SEEDS = 1000        # self-check trials grow with the seeds: bound the loop


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 1 <= value <= MAX_SEEDS:
        raise argparse.ArgumentTypeError(f"expected an integer in [1, {MAX_SEEDS}], got {text!r}")
    return value


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", nargs="?", metavar="RUN_DIR_OR_CSV", type=Path,
                        help="a run directory or an interchange CSV (not with --self-check)")
    parser.add_argument("--config", help="campaign YAML of the cell (nominal model, noise specs)")
    parser.add_argument("--json", type=Path, metavar="OUT.json", help="write the report (or self-check) as JSON")
    parser.add_argument("--plots", type=Path, metavar="DIR", help="write PNG maps (needs matplotlib)")
    parser.add_argument("--html", type=Path, metavar="FILE",
                        help="HTML report (default for a run directory: RUN_DIR/report.html, with RUN_DIR/diagnosis.json)")
    parser.add_argument("--self-check", action="store_true",
                        help="simulate campaigns with withheld effects and check the diagnosis finds them")
    parser.add_argument("--seeds", type=_positive_int, default=5, metavar="N",
                        help="self-check: seeds per effect and per failure class (default 5; 2N controls, 2N "
                             "two-effect cases, N outside the library)")
    parser.add_argument("--force", action="store_true",
                        help="override failed plausibility checks (the report says they were overridden)")
    overwrite_argument(parser)
    width_argument(parser)


@command("diagnose", "diagnose the sim-to-real gap: where it lies, which effect causes it, how far it shrinks",
         _arguments)
def cmd_diagnose(args: argparse.Namespace) -> int:
    if args.self_check:
        if args.source is not None or args.config or args.plots or args.html:
            raise DataError("diagnose", "--self-check takes no data, --config or --plots (only --seeds, --json)")
        return _self_check(args)
    if args.source is None or not args.config:
        raise DataError("diagnose", "needs RUN_DIR_OR_CSV and --config CONFIG (or --self-check)")
    from campaign.cli.common import print_plausibility
    from campaign.config.load import load_cell
    from campaign.report.diagnosis_text import render
    from campaign.calibrate.plausibility import Plausibility
    from campaign.workflows import DiagnoseOutputs, diagnose

    cell = load_cell(args.config)
    out = stdout_console()
    outputs = DiagnoseOutputs(args.json, args.plots, args.html, args.overwrite)   # checked before any work
    result, write = diagnose(args.source, cell, outputs, force=args.force,
                             on_written=lambda line: out.print(line, markup=False))
    render(out, result.report)
    plaus = result.report.get("plausibility")                 # the diagnosis document carries its JSON
    print_plausibility(out, None if plaus is None else Plausibility.from_dict(plaus))
    write()                                       # --json, --plots, RUN_DIR/diagnosis.json + report.html or --html
    return EXIT_OK


def _self_check(args: argparse.Namespace) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from campaign.report.diagnosis_text import render_self_check
    from campaign.calibrate.diagnosis import write_diagnosis_json
    from robocal.diagnose.selfcheck import run_self_check, trial_plan

    out = stdout_console()
    total = len(trial_plan(args.seeds))
    out.print(f"self-check: {total} simulated campaigns from robocal/simulation/truth_cell.py ({args.seeds} seeds per effect, controls, "
              "two-effect cases, an effect outside the library)", markup=False)
    with Progress(TextColumn("diagnosing"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=out, disable=not out.is_terminal) as bar:
        task = bar.add_task("trials", total=total)
        result = run_self_check(args.seeds, progress=lambda i, n, trial: bar.update(task, completed=i))
    render_self_check(out, result)
    if args.json:
        write_diagnosis_json(args.json, result.to_dict())
        out.print(f"wrote {args.json}", markup=False)
    if not result.passed():
        stderr_console().print("self-check below target: an effect or failure class named right in < 95 % of its trials, an "
                        "effect accepted on a control, a confound class not named, or a lag called backlash",
                        style="red", markup=False)
        return EXIT_FAILED
    return EXIT_OK
