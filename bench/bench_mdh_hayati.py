"""Hayati's beta in modified DH: what the placement costs on a large arm and on a desktop arm.

The same simulated campaign (the shipped config's mock cell: truth = its nominal + seeded geometric errors, its
plan) is calibrated three times from the same data:
  DH        the table in standard DH, beta on the transform between the parallel axes (row j);
  MDH       the same robot entered in modified DH (row i takes alpha, a of DH row i-1; exact, same flange frames),
            beta where ``robot.hayati_joints`` now puts it (row j + 1, the transform between the parallel axes);
  MDH-old   the modified-DH table with beta on row j, where the project put it before (between axes j-1 and j).
For a standard-DH config (irb2600) the MDH form is derived; for a modified-DH config (meca500_mdh) the DH form.
It prints the held-out RMS of each (mm), its ratio to the noise floor and the cost of the old placement.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_mdh_hayati.py [--configs irb2600 meca500_mdh]
        [--seeds 1 2 3]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.data.dataset import Dataset  # noqa: E402
from tests.campaign.helpers import simulated_campaign  # noqa: E402  (the plan measured once on the simulated cell)


def other_form(doc: dict) -> dict:
    """The config ``doc`` with its table in the other convention (exact: both give the same flange frames when the
    modified table's first row and the standard table's last row have alpha = a = 0)."""
    rows, conv = doc["robot"]["joints"], doc["robot"]["convention"]
    al, a = [r["alpha_deg"] for r in rows], [r["a_mm"] for r in rows]
    if conv == "dh":
        assert al[-1] == 0 and a[-1] == 0, "the last DH row must have alpha = a = 0"
        al, a = [0] + al[:-1], [0] + a[:-1]
    else:
        assert al[0] == 0 and a[0] == 0, "the first MDH row must have alpha = a = 0"
        al, a = al[1:] + [0], a[1:] + [0]
    out = yaml.safe_load(yaml.safe_dump(doc))
    out["robot"]["convention"] = "mdh" if conv == "dh" else "dh"
    for r, x, y in zip(out["robot"]["joints"], al, a):
        r["alpha_deg"], r["a_mm"] = x, y
    return out


def held_out(ds: Dataset, cell) -> tuple[float, float]:
    rep = calibrate_dataset(ds, cell).report
    return rep.final.test.rms_mm, rep.noise_floor_mm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", nargs="+", default=["irb2600", "meca500_mdh"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.configs:
            doc = yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())
            doc["simulation"]["effects"] = []            # geometry only: the placement is what is compared
            doc.pop("calibration", None)
            paths = {}
            for form, d in ((doc["robot"]["convention"], doc), ("mdh" if doc["robot"]["convention"] == "dh"
                                                               else "dh", other_form(doc))):
                paths[form] = Path(tmp) / f"{name}-{form}.yaml"
                paths[form].write_text(yaml.safe_dump(d, sort_keys=False))
            cells = {form: load_cell(p) for form, p in paths.items()}
            k = cells["mdh"].kinematics
            old = tuple(bool(h) for h in np.roll(k.hayati, -1))           # beta one row earlier: joint j's row
            cells["mdh-old"] = replace(cells["mdh"], kinematics=k.with_(hayati=old))
            print(f"{name}: hayati_joints {doc['robot']['hayati_joints']}; beta rows (1-based) DH "
                  f"{[i + 1 for i, h in enumerate(cells['dh'].kinematics.hayati) if h]}, MDH "
                  f"{[i + 1 for i, h in enumerate(k.hayati) if h]}, MDH-old {[i + 1 for i, h in enumerate(old) if h]}")
            source = cells[doc["robot"]["convention"]]
            for seed in args.seeds:
                sim_cell = replace(source, config=replace(source.config, simulation=replace(
                    source.config.simulation, seed=seed)))
                ds = simulated_campaign(sim_cell, seed)
                r = {form: held_out(ds, c) for form, c in cells.items()}
                floor = r["dh"][1]
                line = ", ".join(f"{form} {rms:.4f} mm ({rms / floor:.2f} x floor)" for form, (rms, _) in r.items())
                print(f"  seed {seed}: {line}; MDH/DH {r['mdh'][0] / r['dh'][0]:.3f}, cost of the old placement "
                      f"{100 * (r['mdh-old'][0] / r['mdh'][0] - 1):+.1f} %")


if __name__ == "__main__":
    main()
