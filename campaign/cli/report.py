"""``campaign report``, ``campaign export`` and ``campaign iso9283``.

    campaign report RUN_DIR [--out report.html]
    campaign export MODEL.json [--urdf robot.urdf] [--dh-csv dh.csv] [--robodk robodk.txt] [--name NAME]
    campaign iso9283 CONFIG [--model MODEL.json] [--out RUN_DIR]

Imported by :mod:`campaign.cli`, which registers them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from campaign.cli.common import (EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, _stderr, _stdout, command,
                                 overwrite_argument)
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
    _stdout().print(f"wrote {path} (figures as PNG in {figures_dir(path)})", markup=False)
    return EXIT_OK


def _export_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL.json", type=Path, help="model.json written by run or reprocess")
    parser.add_argument("--urdf", type=Path, metavar="FILE", help="URDF of the calibrated chain (tool = fixed link)")
    parser.add_argument("--dh-csv", type=Path, metavar="FILE", help="CSV table of the calibrated parameters")
    parser.add_argument("--robodk", type=Path, metavar="FILE", help="DH(M) table as RoboDK users enter it by hand")
    parser.add_argument("--name", default="robot", help="robot name in the URDF (default: robot)")
    overwrite_argument(parser)


@command("export", "export a calibrated model as URDF, a DH table (CSV) or a RoboDK DH(M) table", _export_arguments)
def cmd_export(args: argparse.Namespace) -> int:
    from campaign.report.export import export
    from campaign.calibrate.outputs import load_model

    from campaign.run.output_dirs import check_file

    if not (args.urdf or args.dh_csv or args.robodk):
        raise DataError("export", "nothing to write: give --urdf, --dh-csv and/or --robodk")
    for option, path in (("--urdf", args.urdf), ("--dh-csv", args.dh_csv), ("--robodk", args.robodk)):
        if path is not None:
            check_file(path, args.overwrite, option)
    files = export(load_model(args.model), args.urdf, args.dh_csv, args.robodk, args.name)
    _stdout().print(f"wrote {', '.join(str(f) for f in files)}", markup=False)
    return EXIT_OK


def _iso_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="campaign YAML of the cell (plan.grid box, plan.iso9283)")
    parser.add_argument("--model", type=Path, metavar="MODEL.json",
                        help="calibrated model: its registration gives the base frame, and corrected cycles follow "
                             "the nominal ones (before/after certificate)")
    parser.add_argument("--out", type=Path, metavar="RUN_DIR",
                        help="run directory, new or empty (default: output.dir/NAME-TIMESTAMP)")
    overwrite_argument(parser)


@command("iso9283", "ISO 9283 pose accuracy and repeatability test (nominal, and corrected with --model)",
         _iso_arguments)
def cmd_iso9283(args: argparse.Namespace) -> int:
    from campaign.config.load import load_cell
    from campaign.report.terminal import render_iso
    from campaign.workflows import run_iso9283
    from campaign.calibrate.outputs import load_model

    cell = load_cell(args.config)
    model = load_model(args.model) if args.model else None
    out = _stdout()
    result, report = run_iso9283(cell, model, args.out, out, overwrite=args.overwrite)
    o = result.outcome
    if report is None:
        _stderr().print(f"iso9283 {o.exit_status}: {o.reason}", style="red", markup=False)
        return EXIT_INTERRUPTED if o.exit_status == "abort" else EXIT_FAILED
    render_iso(out, report)
    out.print(f"run directory {result.run_dir}: log.jsonl, report.json, report.html", markup=False)
    return EXIT_OK
