"""Speed of one adaptive round: choose the next batch of 10 from 3000 candidates with the model refitted to 100
measured calibration points (issue 32: <= 2 s on one core).

The demo IRB 2600 cell of ``configs/irb2600.yaml`` (its simulated effects: gravity compliance, a J1 gear error, read
-back lag and tracker drift are in the simulation; the mock measurement here uses the pose-dependent ones) with
``plan.kind: adaptive``: 100 of the plan's candidates measured on the simulated cell (its seed, then
random candidates), 3000 other candidates (a seeded sample of the pool). One round = ``adaptive_model.refit`` (the
default process: screen, geometry, effect engine, residual layer by CV) + ``design_terms`` and the candidates'
coverage + ``choose_batch`` (the campaign's rule, ``campaign.plan.adaptive.RULE``); median of ``--repeats`` runs, wall and CPU time, with the split.
``--without-links``: also the same rounds with the link form never offered (``robocal.effects.library.
LINKS_AFTER_LEVERS`` off), interleaved with the others, and the ratio of the medians.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_adaptive_speed.py [--repeats 5] [--without-links]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import robocal.effects.library as library  # noqa: E402
from campaign.calibrate.adaptive_model import design_terms, refit, task_sample  # noqa: E402
from campaign.plan.adaptive import RULE  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.config.simulation import simulated_cell  # noqa: E402
from campaign.data.dataset import Dataset  # noqa: E402
from campaign.plan.build import build_plan  # noqa: E402
from campaign.plan.optimal import tracker_kinematics  # noqa: E402
from robocal.design.adaptive import Coverage, choose_batch  # noqa: E402
from robocal.design.optimal import lever_scaled  # noqa: E402
from robocal.kinematics.models import smr_tracker  # noqa: E402

N_MEASURED, N_CANDIDATES, BATCH = 100, 3000, 10


def setup(tmp: Path):
    d = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())
    d["plan"].update(kind="adaptive", max_points=N_MEASURED)
    d["plan"].pop("order", None)
    path = tmp / "irb2600-adaptive.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    cell = load_cell(path)
    plan = build_plan(cell)
    rng = np.random.default_rng(0)
    seed = [p for p in plan.points if p.set == "calib"]
    ids = {p.point_id for p in seed}
    others = [p for p in plan.candidates if p.point_id not in ids]
    pick = rng.permutation(len(others))
    measured = seed + [others[i] for i in pick[: N_MEASURED - len(seed)]]
    cands = [others[i] for i in pick[N_MEASURED - len(seed): N_MEASURED - len(seed) + N_CANDIDATES]]
    q = np.radians([p.q_deg for p in measured])
    p, _ = simulated_cell(cell).measure(q, rng, {"payload_kg": np.full(len(q), cell.payload_kg)})
    ds = Dataset(tuple(x.point_id for x in measured), ("calib",) * len(q), np.degrees(q), p, source="bench")
    return cell, ds, np.radians([x.q_deg for x in cands]), len(plan.candidates)


def one_round(cell, ds, q_cand):
    t = [time.perf_counter(), time.process_time()]
    cur = refit(ds, cell)
    t1 = time.perf_counter()
    meta = {"payload_kg": np.full(len(q_cand), cell.payload_kg)}
    task = q_cand[task_sample(len(q_cand))]
    terms = design_terms(cur, q_cand, meta, cell.covariance(smr_tracker(cur.kinematics, q_cand)), task,
                         {"payload_kg": np.full(len(task), cell.payload_kg)})
    X = lever_scaled(tracker_kinematics(cell), np.vstack([q_cand, np.radians(ds.q_deg)]))
    cover = Coverage(X[:len(q_cand)], X[len(q_cand):])     # as ``adaptive_rounds.decide_round`` builds it
    t2 = time.perf_counter()
    b = choose_batch(terms, BATCH, np.ones(len(q_cand), bool), RULE, cover)
    t3 = time.perf_counter()
    return (t3 - t[0], time.process_time() - t[1], t1 - t[0], t2 - t1, t3 - t2), cur, b


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--without-links", action="store_true", help="also time the rounds without the link form")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        cell, ds, q_cand, pool = setup(Path(d))
    runs, off = [], []
    for _ in range(args.repeats):
        times, cur, b = one_round(cell, ds, q_cand)
        runs.append(times)
        if args.without_links:
            with mock.patch.object(library, "LINKS_AFTER_LEVERS", False):
                off.append(one_round(cell, ds, q_cand)[0])
    r = np.median(np.array(runs), axis=0)
    print(f"{len(ds)} measured points, {len(q_cand)} candidates (of a pool of {pool}), batch of {BATCH}; layer "
          f"{cur.layer_kind}, effects {[e.name for e in cur.effects]}")
    print(f"one round: median wall {r[0]:.2f} s (CPU {r[1]:.2f} s; min wall {min(x[0] for x in runs):.2f}, max "
          f"{max(x[0] for x in runs):.2f}) over {args.repeats} runs; target <= 2 s on one core")
    print(f"  refit {r[2]:.2f} s, design terms {r[3]:.2f} s, greedy batch {r[4]:.2f} s")
    if off:
        o = np.median(np.array(off), axis=0)
        print(f"without the link form: median wall {o[0]:.2f} s (refit {o[2]:.2f} s); with / without {r[0] / o[0]:.2f}")


if __name__ == "__main__":
    main()
