"""``campaign import``: a campaign measured in another layout -> the interchange CSV.

    campaign import target-dif CALIB.csv [TEST.csv] --out data.csv [--dif-sign +1|-1]

Imported by :mod:`campaign.cli`, which registers it. The layouts and their rules are in :mod:`campaign.data.importers`.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from campaign.cli.common import EXIT_OK, stdout_console, command, overwrite_argument


def _import_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("layout", choices=("target-dif",),
                        help="target-dif: step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif,joint_1..joint_n, one file per set "
                             "(the public UR5 campaign in tests/data/serial_robots_datasets)")
    parser.add_argument("calib", metavar="CALIB.csv", type=Path, help="the calibration points (set calib)")
    parser.add_argument("test", metavar="TEST.csv", type=Path, nargs="?", help="held-out points (set test), optional")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE", help="interchange CSV to write")
    parser.add_argument("--dif-sign", choices=("+1", "-1"), default="+1",
                        help="measured = target + SIGN x dif (default +1: dif = reached - target; see docs/results.md)")
    overwrite_argument(parser)


@command("import", "convert a campaign measured in another layout to the interchange CSV", _import_arguments)
def cmd_import(args: argparse.Namespace) -> int:
    from campaign.data.importers import import_target_dif
    from campaign.data.interchange_csv import write_csv
    from campaign.run.output_dirs import check_file

    check_file(args.out, args.overwrite)
    ds = import_target_dif(args.calib, args.test, float(args.dif_sign))
    write_csv(args.out, ds)
    n_cal, n_test = int(ds.mask("calib").sum()), int(ds.mask("test").sum())
    stdout_console().print(f"wrote {args.out}: {n_cal} calib + {n_test} test rows in measurement order (step_order), "
                    f"xyz = target {args.dif_sign[0]} dif", markup=False)
    return EXIT_OK
