"""Scale: ``campaign reprocess`` (default config), ``campaign diagnose`` and ``campaign select`` on large interchange CSVs.

A seeded simulated campaign of the IRB 2600 cell (configs/irb2600.yaml: its simulated truth, tracker noise and
robot repeatability) is written as an interchange CSV of N rows: random joint configurations in the middle of
the joint ranges, 85 % calib / 15 % test, three check poses repeated every 50 points, 2 s per point. Each command
runs as a subprocess (``python3 -m campaign ...`` from this checkout); printed: wall time, CPU time and the
child's peak resident memory (``resource.getrusage(RUSAGE_CHILDREN)``: one child per measurement, each run in a
fresh interpreter), the exit code (4, the config's acceptance verdict FAIL with every output written, is a finished
run: configs/irb2600.yaml's max bound is set for its ~94 test points, not for thousands), and the bounds with
PASS/FAIL per line: at 200 000 rows reprocess <= 90 s, diagnose <= 120 s, select <= 60 s; at 1 000 000 rows each
<= 300 s; every command <= 2 GiB at both sizes. Time is judged on the CPU time (one core: the campaign runs BLAS
on one thread); the wall time is printed beside it with the machine's load average (wall times on a shared machine
grow with it).

    python bench/bench_scale.py [--rows 1000,20000,200000] [--commands reprocess,diagnose,select] [--keep DIR]
                                [--threads N]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from campaign.config.simulation import simulated_cell  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.data.dataset import Dataset  # noqa: E402
from campaign.data.interchange_csv import write_csv  # noqa: E402

CONFIG = ROOT / "configs" / "irb2600.yaml"
BOUNDS = {200_000: {"reprocess": (90.0, 2048.0), "diagnose": (120.0, 2048.0), "select": (60.0, 2048.0)},
          1_000_000: {"reprocess": (300.0, 2048.0), "diagnose": (300.0, 2048.0), "select": (300.0, 2048.0)}}
SELECT_POINTS = 300     # calibration rows ``campaign select`` keeps
COMPLETED = (0, 4)      # exit codes of a finished command: 4 = every output written, the config's acceptance FAIL


def simulated_dataset(n_rows: int, seed: int = 0, config: Path = CONFIG) -> Dataset:
    """A seeded campaign of ``n_rows`` rows measured on the config's simulated cell (see module doc)."""
    model = load_cell(config)
    cfg, cell = model.config, simulated_cell(model)
    rng = np.random.default_rng(seed)
    lo = np.array([j.q_min_deg for j in cfg.robot.joints])
    hi = np.array([j.q_max_deg for j in cfg.robot.joints])
    mid, half = (lo + hi) / 2, np.minimum((hi - lo) / 2, 170.0) * 0.6
    n_check_every, n_check = 50, 3
    n_points = int(np.ceil(n_rows / (1 + n_check / n_check_every)))
    q_pts = rng.uniform(mid - half, mid + half, (n_points, len(lo)))
    q_chk = rng.uniform(mid - half, mid + half, (n_check, len(lo)))
    sets = np.where(rng.random(n_points) < 0.85, "calib", "test")
    rows_q, rows_set, rows_id = [], [], []
    for start in range(0, n_points, n_check_every):
        stop = min(start + n_check_every, n_points)
        rows_q.append(q_pts[start:stop])
        rows_set += sets[start:stop].tolist()
        rows_id += [f"P{i:06d}" for i in range(start, stop)]
        rows_q.append(q_chk)
        rows_set += ["check"] * n_check
        rows_id += [f"C{k}" for k in range(n_check)]
    q_deg = np.concatenate(rows_q)[:n_rows]
    p, _ = cell.measure(np.radians(q_deg), rng)
    return Dataset(tuple(rows_id[:n_rows]), tuple(rows_set[:n_rows]), q_deg, p, t_s=np.arange(n_rows) * 2.0,
                   source="bench_scale")


def run_measured(args: list[str], env: dict) -> tuple[int, float, float, float, str]:
    """(exit code, wall s, CPU s (user + system), peak RSS MiB, last stderr line) of ``python3 -m campaign ARGS``
    in a fresh child (measured through a tiny wrapper so each child's figures are its own)."""
    wrapper = ("import resource, subprocess, sys\n"
               "rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode\n"
               "u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
               "print(rc, u.ru_maxrss, u.ru_utime + u.ru_stime)\n")
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", wrapper, sys.executable, "-m", "campaign", *args], cwd=ROOT,
                         env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    rc, rss_kib, cpu = out.stdout.split()[-3:]
    err = [ln for ln in out.stderr.splitlines() if ln.strip()]
    return int(rc), wall, float(cpu), int(rss_kib) / 1024.0, err[-1] if err else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default="1000,20000,200000", help="comma-separated row counts")
    ap.add_argument("--commands", default="reprocess,diagnose,select", help="comma-separated commands to time")
    ap.add_argument("--keep", type=Path, help="keep the CSVs and outputs in this directory")
    ap.add_argument("--threads", help="BLAS threads of the children (default: the campaign's own default, one "
                    "thread, unless this environment sets OPENBLAS_NUM_THREADS / OMP_NUM_THREADS / MKL_NUM_THREADS)")
    a = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if a.threads:
        env.update(OPENBLAS_NUM_THREADS=a.threads, OMP_NUM_THREADS=a.threads, MKL_NUM_THREADS=a.threads)
    blas = {k: env[k] for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS") if k in env}
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} (wall times grow with the load; CPU "
          f"times much less), BLAS threads {blas or 'campaign default (1)'}")
    with tempfile.TemporaryDirectory() as tmp:
        base = a.keep or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        print(f"{'rows':>8} {'command':<10} {'exit':>4} {'wall s':>8} {'CPU s':>8} {'peak MiB':>9}  bound (CPU s, MiB)")
        for n in (int(s) for s in a.rows.split(",")):
            csv = base / f"scale_{n}.csv"
            write_csv(csv, simulated_dataset(n))
            args = {"reprocess": ["reprocess", str(csv), "--config", str(CONFIG), "--out", str(base / f"rep_{n}"), "--overwrite"],
                    "diagnose": ["diagnose", str(csv), "--config", str(CONFIG), "--json", str(base / f"diag_{n}.json")],
                    "select": ["select", str(csv), "--config", str(CONFIG), "--points", str(SELECT_POINTS),
                               "--out", str(base / f"select_{n}.csv"), "--overwrite"]}
            for name in a.commands.split(","):
                rc, wall, cpu, mib, last = run_measured(args[name], env)
                done = rc in COMPLETED
                bound = BOUNDS.get(n, {}).get(name)
                verdict = "" if bound is None else (
                    f"<= {bound[0]:.0f} s, <= {bound[1]:.0f} MiB: "
                    + ("PASS" if done and cpu <= bound[0] and mib <= bound[1] else "FAIL")
                    + (f" (wall {wall:.0f} s > {bound[0]:.0f} s at load {os.getloadavg()[0]:.1f})"
                       if done and wall > bound[0] else ""))
                print(f"{n:>8} {name:<10} {rc:>4} {wall:>8.1f} {cpu:>8.1f} {mib:>9.0f}  {verdict}", flush=True)
                if rc != 0:
                    print(f"{'':>8} {name} stderr: {last}")


if __name__ == "__main__":
    main()
