"""``campaign report``, ``campaign export`` and ``campaign iso9283``.

    campaign report RUN_DIR [--out report.html]
    campaign export MODEL.json [--urdf robot.urdf [--config CONFIG] [--effort-nm N[,N...]]] [--dh-csv dh.csv]
                   [--robodk robodk.txt] [--name NAME]
    campaign iso9283 CONFIG [--model MODEL.json] [--out RUN_DIR]

Imported by :mod:`campaign.cli`, which registers them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from campaign.cli.common import (EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, stderr_console, stdout_console, command,
                                 overwrite_argument, width_argument)
from campaign.errors import DataError


def _report_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", type=Path,
                        help="a run or output directory with report.json, diagnosis.json or verify-*/verify.json")
    parser.add_argument("--out", type=Path, metavar="FILE",
                        help="HTML file (default RUN_DIR/report.html); its figures go to FILE-STEM_figures/")
    overwrite_argument(parser)


@command("report", "write the self-contained HTML report of a run (figures also as PNG)", _report_arguments)
def cmd_report(args: argparse.Namespace) -> int:
    from campaign.report.html import figures_dir, write_report

    path = write_report(args.run_dir, args.out, args.overwrite)
    stdout_console().print(f"wrote {path} (figures as PNG in {figures_dir(path)})", markup=False)
    return EXIT_OK


def _export_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL.json", type=Path, help="model.json written by run or reprocess")
    parser.add_argument("--urdf", type=Path, metavar="FILE",
                        help="URDF of the calibrated chain (tool = fixed link); its joint limits come from --config, or from "
                             "RUN/config.yaml when MODEL.json is a run's")
    parser.add_argument("--config", help="campaign YAML of the cell: joint limits and robot.max_joint_speed_deg_s "
                                         "for the URDF")
    parser.add_argument("--effort-nm", type=_torques, metavar="N[,N...]",
                        help="datasheet joint torque limits for the URDF (N*m, one for all joints or one per "
                             "joint; default: effort omitted)")
    parser.add_argument("--dh-csv", type=Path, metavar="FILE", help="CSV table of the calibrated parameters")
    parser.add_argument("--robodk", type=Path, metavar="FILE", help="DH(M) table as RoboDK users enter it by hand")
    parser.add_argument("--name", default="robot", help="robot name in the URDF (default: robot)")
    overwrite_argument(parser)


@command("export", "export a calibrated model as URDF, a DH table (CSV) or a RoboDK DH(M) table", _export_arguments)
def cmd_export(args: argparse.Namespace) -> int:
    from campaign.report.export import export_model
    from campaign.calibrate.outputs import load_model

    from campaign.run.output_dirs import check_file

    if not (args.urdf or args.dh_csv or args.robodk):
        raise DataError("export", "nothing to write: give --urdf, --dh-csv and/or --robodk")
    for option, path in (("--urdf", args.urdf), ("--dh-csv", args.dh_csv), ("--robodk", args.robodk)):
        if path is not None:
            check_file(path, args.overwrite, option)
    model = load_model(args.model)
    config = args.config or (_run_config(args.model) if args.urdf else None)
    limits = _urdf_limits(args, model, config) if args.urdf and config else None     # export: --urdf needs them
    files = export_model(model, args.urdf, args.dh_csv, args.robodk, args.name, limits)
    if limits is not None and not args.config:
        stdout_console().print(f"URDF joint limits and speeds from {config} (the config of the run that wrote "
                        f"{args.model.name}; --config CONFIG to take another)", markup=False)
    stdout_console().print(f"wrote {', '.join(str(f) for f in files)}", markup=False)
    if limits is not None and limits.effort_nm is None:
        stdout_console().print("URDF: joint effort limits omitted (no --effort-nm); tools that require them (urdfdom, "
                        "ROS) need the datasheet torques", markup=False)
    return EXIT_OK


def _torques(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N*m values separated by commas, got {text!r}") from None
    if any(not v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"expected positive torques, got {text!r}")
    return values


def _run_config(model: Path) -> Path | None:
    """The config of the run whose directory holds ``model`` (RUN/config.yaml), None elsewhere."""
    from campaign.run.output_dirs import is_run_dir

    config = model.parent / "config.yaml"
    return config if model.parent.is_dir() and is_run_dir(model.parent) and config.is_file() else None


def _urdf_limits(args: argparse.Namespace, model, config):
    """The URDF's joint limits from ``config`` (--config or the run's; it must describe the model's robot) and
    --effort-nm."""
    from campaign.config.load import load_cell
    from campaign.correct.targets import check_model_fits
    from campaign.report.export import UrdfLimits

    cell = load_cell(config)
    check_model_fits(cell, model, str(args.model))
    return UrdfLimits.of_config(cell.config, args.effort_nm)


def _iso_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="campaign YAML of the cell (plan.grid box, plan.iso9283)")
    parser.add_argument("--model", type=Path, metavar="MODEL.json",
                        help="calibrated model: its registration gives the base frame, and corrected cycles follow "
                             "the nominal ones (before/after certificate)")
    parser.add_argument("--out", type=Path, metavar="RUN_DIR",
                        help="run directory, new or empty (default: MODEL_DIR/iso9283-TIMESTAMP when the model "
                             "lies beside its calibration report, listed there; else output.dir/NAME-TIMESTAMP)")
    overwrite_argument(parser)
    width_argument(parser)


@command("iso9283", "ISO 9283 pose accuracy and repeatability test (nominal, and corrected with --model)",
         _iso_arguments)
def cmd_iso9283(args: argparse.Namespace) -> int:
    from campaign.config.load import load_cell
    from campaign.report.terminal import render_iso
    from campaign.workflows import run_iso9283
    from campaign.calibrate.outputs import load_model

    cell = load_cell(args.config)
    model = load_model(args.model) if args.model else None
    out = stdout_console()
    result, report = run_iso9283(cell, model, args.out, out, overwrite=args.overwrite, model_path=args.model)
    o = result.outcome
    if report is None:
        stderr_console().print(f"iso9283 {o.exit_status}: {o.reason}", style="red", markup=False)
        return EXIT_INTERRUPTED if o.exit_status == "abort" else EXIT_FAILED
    render_iso(out, report)
    out.print(f"run directory {result.run_dir}: log.jsonl, report.json, report.html", markup=False)
    link = (report.get("model") or {}).get("calibration_report")
    if link:
        from campaign.report.iso9283 import calibration_dir, is_iso_run_of

        cal = calibration_dir(args.model)
        listed = cal is not None and is_iso_run_of(result.run_dir, cal)
        out.print(f"calibration report of the model: {(result.run_dir / link).resolve()}"
                  + (" (written again: it lists this report)" if listed else ""), markup=False)
    return EXIT_OK
