"""``campaign validate|run|plan|reprocess|select|correct|verify``: the campaign's own subcommands.

Each registers itself with :func:`campaign.cli.common.command`; each handler receives the parsed
``argparse.Namespace`` and returns the exit code.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from campaign.cli.common import (EXIT_ACCEPTANCE_FAIL, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, command,
                                 overwrite_argument, print_plausibility, stderr_console, stdout_console,
                                 width_argument)
from campaign.config.load import load_cell
from campaign.errors import DataError



def _config_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="campaign YAML file (see configs/irb2600.yaml)")


@command("validate", "check a campaign config file and print a summary", _config_argument)
def cmd_validate(args: argparse.Namespace) -> int:
    """Load and validate CONFIG (the checks of every command, the cell model's included); print a one-line
    summary."""
    cell = load_cell(args.config)
    cfg = cell.config
    stdout_console().print(
        f"OK {cfg.source_path}: {cfg.name}: {cfg.robot.model}, {cfg.robot.n_joints} joints, "
        f"robot {cfg.robot.url}, tracker {cfg.tracker.url}",
        style="green",
        markup=False,
    )
    _warn_acceptance(cell)
    return EXIT_OK


def _warn_acceptance(cell, plan=None) -> None:
    """One warning line on stderr per acceptance bound below what the noise the specs predict allows (at the plan's
    test points when there is a plan)."""
    from campaign.plan.acceptance import acceptance_warnings

    for line in acceptance_warnings(cell, plan):
        stderr_console().print(f"warning: {line}", style="yellow", markup=False)


def _run_arguments(parser: argparse.ArgumentParser) -> None:
    _config_argument(parser)
    parser.add_argument("--out", metavar="RUN_DIR", type=Path,
                        help="run directory, new or empty (default: output.dir/NAME-TIMESTAMP)")
    parser.add_argument("--resume", metavar="RUN_DIR", type=Path, help="continue an interrupted or paused run")
    _force_argument(parser)
    overwrite_argument(parser)
    width_argument(parser)


@command("run", "measure the plan on the cell's robot and tracker, then calibrate and report", _run_arguments)
def cmd_run(args: argparse.Namespace) -> int:
    from campaign.calibrate.outputs import run_files
    from campaign.workflows import run_campaign

    cell = load_cell(args.config)
    out = stdout_console()
    result = run_campaign(cell, args.out, args.resume, out, overwrite=args.overwrite, force=args.force)
    o = result.outcome
    if o.exit_status != "success":
        hint = f"; continue with: campaign run {args.config} --resume {result.run_dir}"
        stderr_console().print(f"run {o.exit_status}: {o.reason}{hint}", style="red", markup=False)
        return EXIT_INTERRUPTED if o.exit_status == "abort" else EXIT_FAILED
    if result.iso9283 is not None:                     # plan.kind: iso9283
        from campaign.report.terminal import render_iso
        render_iso(out, result.iso9283)
        out.print(f"run directory {result.run_dir}: log.jsonl, report.json, report.html, report_figures/ (PNG)",
                  markup=False)
        return EXIT_OK
    _print_calibration(out, result.processed.report)
    out.print(f"run directory {result.run_dir}: " + ", ".join(run_files(result.processed)), markup=False)
    return _verdict_exit(result.processed.report, result.run_dir)


def _print_calibration(out: Console, report) -> None:
    """The calibration's summary first (banner, model, held-out figures, verdict), then its tables and lines."""
    from campaign.report.summary_text import render_summary
    from campaign.report.terminal import render_parameters, render_stages, render_stop

    render_summary(out, report.summary)
    render_stages(out, report)
    render_parameters(out, report)
    render_stop(out, report)
    from campaign.report.adaptive_text import render_learning
    render_learning(out, report.learning)
    print_plausibility(out, report.plausibility)


def _plan_arguments(parser: argparse.ArgumentParser) -> None:
    _config_argument(parser)
    parser.add_argument("--csv", metavar="FILE", type=Path, help="also write the plan as CSV")
    overwrite_argument(parser)
    width_argument(parser)


@command("plan", "build the measurement plan and print a summary (dry run, nothing moves)", _plan_arguments)
def cmd_plan(args: argparse.Namespace) -> int:
    from campaign.run.eta import estimate_duration_s
    from campaign.plan.build import build_plan
    from campaign.plan.points import write_plan_csv
    from campaign.report.terminal import render_plan

    from campaign.run.output_dirs import check_file

    cell = load_cell(args.config)
    if args.csv:
        check_file(args.csv, args.overwrite, "--csv")
    plan = build_plan(cell)
    render_plan(stdout_console(), plan, estimate_duration_s(plan.points, cell))
    _warn_acceptance(cell, plan)
    if cell.config.plan.kind != "iso9283" and plan.count("calib"):
        from campaign.plan.optimal import plan_forecast
        from campaign.report.terminal import render_forecast
        render_forecast(stdout_console(), plan_forecast(cell, plan), () if plan.candidates else plan.blocks)
        from campaign.calibrate.learning import plan_learning
        from campaign.report.adaptive_text import render_plan_learning
        render_plan_learning(stdout_console(), *plan_learning(cell, plan))
    if args.csv:
        write_plan_csv(plan, args.csv)
    return EXIT_OK


def _reprocess_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", metavar="RUN_DIR_OR_CSV", type=Path, help="a run directory or an interchange CSV")
    parser.add_argument("--config", required=True, help="campaign YAML of the cell (nominal model, noise, options)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="where report.json, model.json and report.html go: a new or empty directory (or one "
                             "reprocess wrote from the same source); never a run's directory")
    _force_argument(parser)
    overwrite_argument(parser)
    width_argument(parser)


@command("reprocess", "calibrate and report offline from a run directory or an interchange CSV", _reprocess_arguments)
def cmd_reprocess(args: argparse.Namespace) -> int:
    from campaign.calibrate.outputs import output_files
    from campaign.workflows import reprocess

    cell = load_cell(args.config)
    if not args.source.exists():
        raise DataError(str(args.source), "no such file or run directory")
    processed = reprocess(args.source, cell, args.out, args.overwrite, force=args.force)
    out = stdout_console()
    _print_calibration(out, processed.report)
    out.print(f"wrote into {args.out}: " + ", ".join(output_files(processed)), markup=False)
    return _verdict_exit(processed.report, args.out)


def _verdict_exit(report, out_dir: Path) -> int:
    """EXIT_ACCEPTANCE_FAIL with one line on stderr when the verdict against ``acceptance`` is FAIL (the outputs are
    written all the same), else EXIT_OK."""
    from campaign.calibrate.summary import FAIL

    v = None if report.summary is None else report.summary.verdict
    if v is None or v.result != FAIL:
        return EXIT_OK
    stderr_console().print(f"acceptance FAIL ({', '.join(v.failed)} exceeded on the held-out test set): every output is "
                    f"written in {out_dir}; exit {EXIT_ACCEPTANCE_FAIL}", style="red", markup=False)
    return EXIT_ACCEPTANCE_FAIL


def _select_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", metavar="DATA", type=Path,
                        help="a measured campaign: an interchange CSV or a run directory (its log)")
    parser.add_argument("--config", required=True, help="campaign YAML of the cell (nominal model, noise)")
    parser.add_argument("--points", required=True, type=int, metavar="N", help="calibration rows to keep")
    parser.add_argument("--out", required=True, type=Path, metavar="SUBSET.csv", help="the subset (interchange CSV)")
    parser.add_argument("--adaptive", action="store_true",
                        help="replay an adaptive campaign: a space-filling seed, then batches continuing it "
                             "farthest-first, each round judged by the model refitted to the rows chosen so far "
                             "(only their measurements)")
    overwrite_argument(parser)
    _force_argument(parser)


@command("select", "choose N calibration rows of a measured campaign (space-filling, the geometry determined; or "
                   "--adaptive: replayed batch by batch with the model refitted)",
         _select_arguments)
def cmd_select(args: argparse.Namespace) -> int:
    from campaign.report.terminal import render_selection
    from campaign.workflows import select

    cell = load_cell(args.config)
    sel, ds = select(args.data, cell, args.points, args.out, adaptive=args.adaptive, overwrite=args.overwrite,
                     force=args.force)
    if args.adaptive:
        from campaign.report.adaptive_text import render_adaptive_selection
        render_adaptive_selection(stdout_console(), sel, int((~ds.mask("calib")).sum()), args.out)
    else:
        render_selection(stdout_console(), sel, int((~ds.mask("calib")).sum()), args.out)
    return EXIT_OK


def _correct_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True, help="campaign YAML of the cell")
    parser.add_argument("--model", required=True, type=Path, help="model.json written by run or reprocess")
    parser.add_argument("--targets", required=True, type=Path,
                        help="CSV target_id,x,y,z[,qw,qx,qy,qz] in mm in the robot base frame (a path: one row per point)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="where the corrected targets go: a new or empty directory (or one correct wrote with "
                             "the same model)")
    overwrite_argument(parser)
    parser.add_argument("--format", action="append", choices=("rapid", "ur", "csv"), metavar="FORMAT",
                        help="write-back format: rapid, ur or csv (repeatable; default: the configured "
                             "controller's format and csv)")
    _force_argument(parser)


@command("correct", "correct Cartesian targets with a calibrated model and write controller files", _correct_arguments)
def cmd_correct(args: argparse.Namespace) -> int:
    from campaign.correct.accuracy import summary_lines
    from campaign.workflows import correct

    cell = load_cell(args.config)
    out = stdout_console()
    done = correct(cell, args.model, args.targets, args.out, tuple(args.format or ()), overwrite=args.overwrite,
                   force=args.force, on_rejected=lambda n: _print_rejected(out, n, args.out))
    out.print(f"{done.n_targets - len(done.refused)} of {done.n_targets} targets corrected; wrote "
              f"{', '.join(p.name for p in done.paths)} in {args.out}", markup=False)
    for line in summary_lines(done.written, done.held_out, cell.config.correction.threshold_mm):
        out.print(line, markup=False)
    return EXIT_OK


def _print_rejected(out: Console, n_targets: int, out_dir: Path) -> None:
    """Summary of the rejected targets (all of them are in rejected.csv with their reason)."""
    from campaign.correct.write_back import read_rejected

    rows = read_rejected(out_dir)
    if not rows:
        return
    out.print(f"{len(rows)} of {n_targets} targets rejected (never written; reasons in {out_dir}/rejected.csv):",
              markup=False)
    for target_id, reason in rows[:10]:
        out.print(f"  {target_id}: {reason}", markup=False)
    if len(rows) > 10:
        out.print(f"  ... and {len(rows) - 10} more", markup=False)


def _verify_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", type=Path, help="a finished run (with model.json)")
    _force_argument(parser)
    width_argument(parser)


@command("verify", "measure the run's test points after correction (closed loop) and report before/after",
         _verify_arguments)
def cmd_verify(args: argparse.Namespace) -> int:
    from campaign.workflows import verify
    from campaign.report.terminal import render_verify

    result = verify(args.run_dir, stdout_console(), force=args.force)
    render_verify(stdout_console(), result.report)
    stdout_console().print(f"wrote {result.out_dir}/verify.json and log.jsonl", markup=False)
    if result.exit_status != "success":
        stderr_console().print(f"verify {result.exit_status}: {result.reason}", style="red", markup=False)
        return EXIT_FAILED
    return EXIT_OK


def _force_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true",
                        help="override failed plausibility checks (wrong robot/unit, rows outside the joint limits, "
                             "implausible deltas, a controller or tracker reporting another model than the "
                             "config's); the report says they were overridden")
