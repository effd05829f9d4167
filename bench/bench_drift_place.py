"""A drift whose clock follows the place: should the effect library still offer it? Held-out RMS of the default
process with and without the check (``robocal.effects.library.LibraryOptions.clock_place_max_r2``).

Protocol (issue 32, fifth; written with the code of the check, before it ran on any data set; this docstring and
that code are committed before the run; nothing about the method, the data or the rule changes after it without
being disclosed beside the figures):
  * What is judged: the registration drift (in time, else in measurement order) and the warm-up (in temperature,
    else in time) are no longer offered when a quadratic in the SMR position explains more than 90 % of their
    clock's variance. Such a clock stands for the place: a serpentine grid measured in order without repeated
    poses. A drift in it can fit a shape in space, and it does not carry to poses measured later. Everything else
    in the default process is unchanged.
  * Why: twice a selection of 50 rows broke down on this (the third protocol's rule ``d`` on seed 8 of the
    UR10-like form, 5.03 x; the fourth protocol's task-covering picks on seed 10 of the IRB 4600-like form,
    3.18 x). Each time the effect selection took a registration drift in measurement order that the form does not
    have. On development data the clock's explained share was 0.98-0.99 on the grid forms and both breakdowns, and
    0.02-0.16 on the random-order truth forms and 0.14 on the UR5 campaign.
  * (i) Where the check can close: the two config forms of ``select_forms.ADAPTIVE_FORMS`` (UR10-like, IRB
    4600-like: serpentine grids, the held-out poses measured after, no timestamps, no repeated poses), fresh seeds
    13 14 15. Per data set: all rows, and the rows of the adaptive replay under rules ``f`` (the campaign's) and
    ``d`` at 50 and 100. The rows are chosen once, with the check off (today's code), then each set is calibrated with
    the check off and on. Figure: the held-out RMS with the check over that without, for each of the 5 sets x 6
    data sets.
  * (ii) The two breakdowns above (known data, not fresh): the same two figures.
  * (iii) Where the check must stay open: the UR5 campaign (all rows, ``f``'s 50 and 100) and the four truth-simulator
    forms (random order over two hours; seeds 13 14 15, all rows and ``f``'s 50). For each, the clock's explained
    share (as this script computes it: whether the check should close) and the two held-out figures.
  * Choice: the check is kept (default 0.9) if over (i) the mean ratio is at most 1.000 and none exceeds 1.05, and
    in (iii) no held-out figure gets worse by more than 1 %. Otherwise the default becomes None (no check).
  * Development before this was fixed: the explained share was computed on seeds 101 of the six forms, the UR5 and
    the two breakdowns (figures above). A clamp of the drift's clock to the calibration rows' span was tried on the
    two breakdowns with a temporary patch (0.1182 -> 0.1057 mm and 0.2533 -> 0.2100 mm): not enough, not kept.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_drift_place.py [--seeds 13 14 15]
        [--parts i ii iii]

Outcome (run on eda2970 as two processes, ``--parts i ii`` and ``--parts iii``, so the last line that applies the rule
was not printed; the rule applied to their printed figures by hand): the check is kept.
  * (i) 30 figures, mean ratio 0.9788, largest 1.000. 29 are identical; one is a breakdown of today's code found on
    fresh data: seed 15 of the IRB 4600-like form, rule ``f`` (the campaign's) at 50 rows, 0.1186 mm without the
    check, 0.0433 with it (all rows 0.0398). The clock's explained share was 0.980-0.995 on every set.
  * (ii) UR10-like seed 8, ``d`` 50: 0.2533 -> 0.0515 mm (all rows 0.0504); IRB 4600-like seed 10, ``f-task`` 50:
    0.1182 -> 0.0383 mm (all rows 0.0371).
  * (iii) 27 figures, every ratio 1.000; the check stayed open on all (explained share 0.018-0.409; the UR5's 50
    rows the highest).
  * After the run, not part of the protocol: the diagnosis self-check's two forms measured in a sweep of J1
    (``order_drift``, ``order_gear``; seeds 900-902) give the same effects, classes and held-out figures with and
    without the check.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from unittest import mock
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import campaign.calibrate.effects_stage as effects_stage  # noqa: E402
from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from robocal.effects.engine import EngineOptions  # noqa: E402
from robocal.effects.library import LibraryOptions, _follows_place  # noqa: E402
from robocal.kinematics.models import smr_base  # noqa: E402
from bench_select_task import task_data  # noqa: E402
from select_forms import ADAPTIVE_FORMS, ur5_dataset  # noqa: E402
from select_replay import rms_off_on  # noqa: E402

GRID_FORMS = ("UR10-like (compliance + J2 gear)", "IRB 4600-like (compliance + J3 gear + coupling)")
TRUTH_FORMS = ("compliance+gear+drift", "strong compliance, sparse far", "read-back lag",
               "layer only (sag outside the library)")


def check_off():
    """The default process without the check (today's library), as a context."""
    return mock.patch.object(effects_stage, "EngineOptions",
                             lambda **kw: EngineOptions(library=LibraryOptions(clock_place_max_r2=None), **kw))


def figures(ds, cell, rows) -> tuple[float, float]:
    """Held-out RMS (mm) without and with the check, on the calibration rows ``rows`` (all when None)."""
    return rms_off_on(ds, cell, rows, check_off)


def explained(ds, cell, rows) -> float:
    """The share of the drift's clock (time, else measurement order) a quadratic in the SMR position explains."""
    clock = ds.t_s if ds.t_s is not None else ds.with_order_context().order_context.order
    q = np.radians(ds.q_deg[rows])
    r2 = _follows_place(np.asarray(clock, float)[rows], lambda: smr_base(cell.kinematics, q),
                        LibraryOptions(clock_place_max_r2=-np.inf))
    return float(r2)


def line(label, off, on, extra="") -> float:
    print(f"  {label:34s} off {off:.4f}  on {on:.4f} mm  ratio {on / off:.3f}{extra}", flush=True)
    return on / off


def part_i(tmp: Path, seeds) -> list[float]:
    ratios = []
    for form in GRID_FORMS:
        for seed in seeds:
            ds, cell = ADAPTIVE_FORMS[form](tmp, seed)
            print(f"{form}, seed {seed}", flush=True)
            with check_off():
                sets = {f"{r} {n}": adaptive_rows(ds, cell, 100, rule=r).order[:n] for r in ("f", "d") for n in (50, 100)}
            cal = np.flatnonzero(ds.mask("calib"))
            ratios.append(line("all rows", *figures(ds, cell, None), f"  (clock explained {explained(ds, cell, cal):.3f})"))
            for label, rows in sets.items():
                ratios.append(line(label, *figures(ds, cell, rows), f"  ({explained(ds, cell, rows):.3f})"))
    r = np.array(ratios)
    print(f"(i) {len(r)} figures: mean ratio {r.mean():.4f}, largest {r.max():.3f}, smallest {r.min():.3f}")
    return ratios


def part_ii(tmp: Path) -> None:
    ds, cell = ADAPTIVE_FORMS[GRID_FORMS[0]](tmp, 8)
    with check_off():
        rows = adaptive_rows(ds, cell, 50, rule="d").order
    line("(ii) UR10-like seed 8, d 50", *figures(ds, cell, rows))
    ds, cell, task_q = task_data(*ADAPTIVE_FORMS[GRID_FORMS[1]](tmp, 10))
    with check_off():
        rows = adaptive_rows(ds, cell, 50, task_q_rad=task_q, cover_task=True).order
    line("(ii) IRB 4600-like seed 10, f-task 50", *figures(ds, cell, rows))


def part_iii(tmp: Path, seeds) -> list[float]:
    ratios = []
    runs = [("UR5 campaign", *ur5_dataset(), (None, 50, 100))]
    runs += [(f"{form}, seed {s}", *ADAPTIVE_FORMS[form](tmp, s), (None, 50)) for form in TRUTH_FORMS for s in seeds]
    for label, ds, cell, sizes in runs:
        order = adaptive_rows(ds, cell, max(n for n in sizes if n), rule="f").order
        for n in sizes:
            rows = np.flatnonzero(ds.mask("calib")) if n is None else order[:n]
            r2 = explained(ds, cell, rows)
            shut = "CLOSES" if r2 > LibraryOptions().clock_place_max_r2 else "open"
            ratios.append(line(f"{label}, {'all rows' if n is None else f'f {n}'}",
                               *figures(ds, cell, None if n is None else rows), f"  ({r2:.3f}: {shut})"))
    r = np.array(ratios)
    print(f"(iii) {len(r)} figures: largest ratio {r.max():.3f}, smallest {r.min():.3f}")
    return ratios


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[13, 14, 15])
    ap.add_argument("--parts", nargs="+", default=["i", "ii", "iii"], choices=["i", "ii", "iii"])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        ratios = part_i(Path(tmp), args.seeds) if "i" in args.parts else None
        if "ii" in args.parts:
            part_ii(Path(tmp))
        worse = part_iii(Path(tmp), args.seeds) if "iii" in args.parts else None
    if ratios is not None and worse is not None:
        keep = np.mean(ratios) <= 1.0 and max(ratios) <= 1.05 and max(worse) <= 1.01
        print(f"check kept: {keep} (i: mean ratio {np.mean(ratios):.4f} <= 1, largest {max(ratios):.3f} <= 1.05; "
              f"iii: largest {max(worse):.3f} <= 1.01)")


if __name__ == "__main__":
    main()
