"""I/O speed: interchange CSV read/write of 100k rows and durable log appends (write + fsync). Prints medians."""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from campaign.data.dataset import Dataset  # noqa: E402
from campaign.data.interchange_csv import read_csv, write_csv  # noqa: E402
from campaign.run.log_writer import RunLog  # noqa: E402


def main(n: int = 100_000, repeats: int = 3) -> None:
    rng = np.random.default_rng(0)
    ds = Dataset(point_id=tuple(f"P{i}" for i in range(n)), set=tuple(rng.choice(["calib", "test"], n)),
                 q_deg=rng.uniform(-180, 180, (n, 6)), p_tracker_mm=rng.uniform(-3000, 3000, (n, 3)),
                 t_s=np.arange(n) * 2.0, temp_c=None, payload_kg=None, p2_tracker_mm=None, p3_tracker_mm=None,
                 sigma_mm=None, source="bench")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        w, r = [], []
        for _ in range(repeats):
            t0 = time.perf_counter(); write_csv(path, ds); w.append(time.perf_counter() - t0)
            t0 = time.perf_counter(); read_csv(path); r.append(time.perf_counter() - t0)
        print(f"interchange CSV, {n} rows: write median {np.median(w):.2f} s, read median {np.median(r):.2f} s")
        log = RunLog.create(Path(tmp) / "run", {"config_sha256": "x", "plan_sha256": "y"})
        rec = {"point_id": "P", "set": "calib", "q_cmd_deg": [0.0] * 6, "p_tracker_mm": [1.0, 2.0, 3.0]}
        times = []
        for i in range(300):
            t0 = time.perf_counter(); log.append_point(dict(rec, point_id=f"P{i}")); times.append(time.perf_counter() - t0)
        log.close()
        print(f"durable log append (one write + fsync): median {1e3 * np.median(times):.3f} ms, "
              f"95th percentile {1e3 * np.quantile(times, 0.95):.3f} ms")


if __name__ == "__main__":
    main()
