"""Nest-drift model selection: leave-one-round-out CV by batched normal-equation downdates (robocal.measure.drift) against
one least-squares fit per held-out round (the implementation before issue 21), on the same simulated nest readings
(three floor nests read after every pose of a robocal.simulation.truth_cell campaign with registration drift, ~880 readings, ~290
rounds). Prints the median time of each, the ratio, and the largest difference of their CV figures.

    OPENBLAS_NUM_THREADS=1 python3 bench/bench_drift.py
"""
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocal.measure.drift import _design, fit_drift, nest_rounds  # noqa: E402
from robocal.simulation.truth_cell import TruthProtocol, simulate  # noqa: E402


def per_round_cv(t, nest, p, degree, rotation):
    """The alternative: a least-squares fit per held-out interior round (the loop fit_drift used to run)."""
    k = int(nest.max()) + 1
    p_mean = np.array([p[nest == j].mean(axis=0) for j in range(k)])
    tau = t / max(np.ptp(t), 1.0)
    rounds = nest_rounds(nest, t)
    err = []
    for r in range(1, int(rounds.max())):
        tr, te = rounds != r, rounds == r
        x, *_ = np.linalg.lstsq(_design(nest[tr], tau[tr], p_mean, degree, rotation), p[tr].reshape(-1), rcond=None)
        err.append(p[te].reshape(-1) - _design(nest[te], tau[te], p_mean, degree, rotation) @ x)
    e = np.concatenate(err)
    return float(np.sqrt(np.sum(e**2) / (len(e) / 3)))


def median_time(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return float(np.median(times)), out


def main():
    camp = simulate(["registration_drift"], 0, TruthProtocol(n_calib=200, n_test=80, check_poses=4, check_repeats=3,
                                                              nest_every=1, payloads_kg=(0.0,)))
    _, nest = np.unique(camp.nest_id, return_inverse=True)
    t, p = camp.nest_t_s, camp.nest_p_mm
    t_new, model = median_time(lambda: fit_drift(t, nest, p))
    t_old, old = median_time(lambda: {f"{d}{'+rotation' if r else ''}": per_round_cv(t, nest, p, d, r)
                                      for d in range(4) for r in ((False, True) if d else (False,))}, repeats=1)
    diff = max(abs(model.cv_rms_mm[k] - v) for k, v in old.items())
    print(f"{len(t)} nest readings, {int(nest_rounds(nest, t).max()) + 1} rounds, 7 candidate models")
    print(f"   batched downdates (fit_drift, whole selection + final fit): median {t_new:.3f} s CPU of 3")
    print(f"   one lstsq per held-out round (CV only): {t_old:.2f} s CPU; ratio x{t_old / t_new:.0f}; "
          f"largest CV difference {diff:.1e} mm; chosen {model.degree}{'+rotation' if model.rotation else ''}")


if __name__ == "__main__":
    main()
