"""Time to write the HTML report of a 1000-point run (target <= 5 s), split into figures and templating, next to
the calibration that produced it (what the operator waits for anyway); and the same report written again, its
figures taken from the run's figures directory (``campaign.report.figure_index``: what ``diagnose``, ``verify`` and
``report --out`` do), as a ratio to drawing them in the same run.

A mock campaign on the IRB 2600 cell with a 1000-point plan (grid + test points + check poses) is measured once;
then ``write_report`` runs ``--repeats`` times each way (to a new file each time) and the medians are printed.

    python bench/bench_report.py [--repeats 3] [--keep DIR]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from rich.console import Console  # noqa: E402

from campaign.config.load import load_cell  # noqa: E402
from campaign.report.html import build_figures, collect, render_html, write_report  # noqa: E402
from campaign.data.interchange_csv import read_csv  # noqa: E402
from campaign.workflows import run_campaign  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402


def thousand_point_config(tmp: Path) -> Path:
    doc = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())
    doc["plan"]["grid"]["step_mm"] = 130          # 7 x 13 x 10 grid, about 800 reachable
    doc["plan"]["test"]["count"] = 200
    doc["plan"]["check_poses"] = {"count": 3, "every_n_points": 100}
    doc["output"] = {"dir": str(tmp / "runs")}
    path = tmp / "irb2600-1000.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def median_s(fn, repeats: int) -> tuple[float, float]:
    """Median (wall, CPU) seconds: on a shared machine the CPU time of this process is the honest figure."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--keep", type=Path, help="keep the run directory here")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_report_")) if args.keep is None else args.keep
    tmp.mkdir(parents=True, exist_ok=True)
    cell = load_cell(thousand_point_config(tmp))
    result = run_campaign(cell, tmp / "run", console=Console(quiet=True))
    run_dir = result.run_dir
    n = result.processed.report.n
    rows = len(result.processed.points)
    print(f"run: {n.calib} calib + {n.test} test + {n.check} check = {rows} points")
    ds = read_csv(run_dir / "data.csv")
    t_cal = median_s(lambda: calibrate_dataset(ds, cell), args.repeats)
    src = collect(run_dir)
    t_fig = median_s(lambda: build_figures(src), args.repeats)
    figs = build_figures(src)
    t_html = median_s(lambda: render_html(src, figs), args.repeats)
    index = run_dir / "report_figures" / "figures.json"
    kept = index.read_bytes()
    index.unlink()                                          # nothing to take: every figure drawn
    outs = iter(range(10**6))
    t_all = median_s(lambda: write_report(run_dir, tmp / f"drawn{next(outs)}.html"), args.repeats)
    index.write_bytes(kept)
    t_again = median_s(lambda: write_report(run_dir, tmp / f"again{next(outs)}.html"), args.repeats)
    size = (run_dir / "report.html").stat().st_size
    print(f"write_report (figures + HTML + PNG files), medians over {args.repeats}: wall {t_all[0]:.2f} s, "
          f"CPU {t_all[1]:.2f} s (target <= 5 s: {'met' if t_all[1] <= 5 else 'NOT met'} on CPU time; wall time "
          f"counts other processes on a shared machine: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
          f"cores); report.html {size / 1e6:.2f} MB, {sum(len(v) for v in figs.values())} figures")
    print(f"  figures wall {t_fig[0]:.2f} s / CPU {t_fig[1]:.2f} s, templating wall {t_html[0]:.3f} s / "
          f"CPU {t_html[1]:.3f} s")
    print(f"  calibration of the same run (process): CPU {t_cal[1]:.2f} s; report / calibration (CPU) = "
          f"{t_all[1] / t_cal[1]:.2f}")
    print(f"written again, figures taken from the run's figures directory: wall {t_again[0]:.2f} s, CPU "
          f"{t_again[1]:.2f} s; ratio to drawing them (CPU) {t_again[1] / t_all[1]:.2f}")


if __name__ == "__main__":
    main()
