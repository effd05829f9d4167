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
    from campaign.calibrate.diagnosis import diagnose_source, write_diagnosis_json
    from campaign.report.diagnosis_text import render
    from campaign.report.diagnosis_plots import write_plots
    from campaign.calibrate.plausibility import Plausibility, forced

    cell = load_cell(args.config)
    plots = _check_outputs(args)                  # every output path refused or accepted before any work
    with forced(args.force):
        result = diagnose_source(args.source, cell)
    out = stdout_console()
    render(out, result.report)
    plaus = result.report.get("plausibility")                 # the diagnosis document carries its JSON
    print_plausibility(out, None if plaus is None else Plausibility.from_dict(plaus))
    if args.json:
        write_diagnosis_json(args.json, result.report)
        out.print(f"wrote {args.json}", markup=False)
    if plots is not None:
        files = write_plots(result.report, plots)
        out.print(files if isinstance(files, str) else f"wrote {', '.join(str(f) for f in files)}", markup=False)
    html = _write_html(args, result.report)       # RUN_DIR/diagnosis.json + report.html, or --html FILE
    if html:
        out.print(f"wrote {html}", markup=False)
    return EXIT_OK


def _check_outputs(args: argparse.Namespace):
    """--json FILE, --plots DIR, --html FILE (or the run directory's diagnosis.json and report.html) checked
    (:mod:`campaign.run.output_dirs`); returns the claim of the plots directory (None without --plots)."""
    from campaign.report.html import report_targets
    from campaign.run.output_dirs import check_campaign_dir, check_dir, check_file, source_key

    if args.json:
        check_file(args.json, args.overwrite, "--json")
    if args.html is not None:                     # a page of the diagnosis alone: never a run's own report.html
        check_file(args.html, args.overwrite, "--html")
        report_targets(args.html.parent, args.html, args.overwrite)
    elif args.source.is_dir():
        check_campaign_dir(args.source, "diagnose")
        report_targets(args.source)
    if args.plots is None:
        return None
    return check_dir(args.plots, "plots", args.overwrite, source=source_key(args.source), option="--plots")


def _write_html(args: argparse.Namespace, report: dict) -> Path | None:
    """The diagnosis as an HTML report: --html FILE (from the diagnosis alone), or the run directory's
    report.html with diagnosis.json beside it."""
    from campaign.calibrate.diagnosis import write_diagnosis_json
    from campaign.report.html import ReportSources, write_report

    if args.html is not None:
        title = f"{report.get('config', 'diagnosis')}: {args.html.stem}"
        return write_report(args.html.parent, args.html, args.overwrite,
                            sources=ReportSources(title, diagnosis=report, files={"diagnosis": "(this command)"}))
    if not args.source.is_dir():
        return None
    write_diagnosis_json(args.source / "diagnosis.json", report)
    return write_report(args.source)


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
