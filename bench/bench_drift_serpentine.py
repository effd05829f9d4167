"""A real tracker drift measured in serpentine order: what the clock-place check of the effect library costs.

The check (``robocal.effects.library.LibraryOptions.clock_place_max_r2``, issue 32's fifth protocol) stops offering a
drift when a quadratic in the SMR position explains more than 90 % of its clock: in a serpentine grid the clock
stands for the place. It was judged on campaigns without a drift, where a drift taken in such a clock was spurious.
This script measures the other side: the demo cell (configs/irb2600.yaml: compliance, a J1 gear error, a read-back
lag, a tracker-registration drift) measured in serpentine order without floor nests, so that only the data can show
the drift, run through ``campaign run`` on the mock cell (its check poses re-measured every 50 points, the test
points interleaved along the path, as the plan orders them). Per seed: the held-out RMS by stage of the default process
with and without the check, and that of the same cell without a drift (with the check). The drift at the demo's
magnitude (0.11 mm/h and 5 urad/h) and at ``--scale`` times it.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_drift_serpentine.py [--seeds 1 2 3] [--scales 1 5]

Figures (run on 961ae92 + this script; final held-out RMS, mm; seeds 1 / 2 / 3):
  * no drift: 0.0332 / 0.0341 / 0.0346.
  * the demo's drift: 0.0333 / 0.0338 / 0.0345 with and without the check. No drift is taken either way.
  * 5 x the demo's drift: without the check, the registration drift in measurement order is taken and gives 0.0332 /
    0.0337 / 0.0346; with it, 0.0349 / 0.0344 / 0.0357 (5 %, 2 %, 3 % higher).
  * The held-out figure applies the fitted drift to the test rows, which share the clock with their neighbours on
    the path. The model written for the robot carries no drift, so this figure is an upper bound on what the check
    costs the delivered model.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_drift_place import check_off  # noqa: E402
from bench_select_stages import stages  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.data.source import load_source  # noqa: E402

DRIFT_KEYS = ("tracker_drift_mm_per_h", "tracker_drift_urad_per_h")


def run(tmp: Path, seed: int, scale: float, label: str):
    """(dataset, cell) of the demo cell, serpentine order, no nests, its drift times ``scale``, measured once."""
    doc = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())
    doc["plan"]["order"] = "serpentine"
    doc["plan"].pop("nests", None)
    doc.pop("acceptance", None)
    doc["simulation"]["seed"] = seed
    for key in DRIFT_KEYS:
        doc["simulation"][key] = [scale * v for v in doc["simulation"][key]]
    doc["output"] = {"dir": str(tmp / "runs")}
    cfg = tmp / f"{label}.yaml"
    cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
    out = tmp / label
    subprocess.run([sys.executable, "-m", "campaign", "run", str(cfg), "--out", str(out)], check=True,
                   capture_output=True)
    return load_source(out / "data.csv").dataset, load_cell(cfg)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 5.0])
    args = ap.parse_args()
    print("held-out RMS by stage (nominal / kinematic / + effects / final), mm")
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            ds0, cell0 = run(Path(tmp), seed, 0.0, "none")
            print(f"seed {seed}, no drift, with the check:    {stages(calibrate_dataset(ds0, cell0).report)}")
            for scale in args.scales:
                ds, cell = run(Path(tmp), seed, scale, f"x{scale:g}")
                with check_off():
                    off = stages(calibrate_dataset(ds, cell).report)
                print(f"seed {seed}, drift x{scale:g}, without the check: {off}")
                print(f"seed {seed}, drift x{scale:g}, with the check:    "
                      f"{stages(calibrate_dataset(ds, cell).report)}", flush=True)


if __name__ == "__main__":
    main()
