"""Small configs derived from the shipped ones, for fast campaign tests; the reports a command wrote, typed."""
from __future__ import annotations

import json
from pathlib import Path

import yaml

from campaign.calibrate.calibration_report import CalibrationReport
from campaign.correct.verify_report import VerifyReport

ROOT = Path(__file__).resolve().parents[2]


def geometric_only(doc: dict) -> dict:
    """The config ``doc`` with the real-cell phenomena of the demo cell switched off: no simulated effects, read-back
    lag or tracker drift, no nests, serpentine order, no payload (a geometric-only truth, for tests of mechanics)."""
    sim = doc.get("simulation", {})
    sim["effects"] = []
    for key in ("readback_lag_deg_per_deg", "readback_noise_deg", "tracker_drift_mm_per_h", "tracker_drift_urad_per_h",
                "tracker_drift_tau_s"):
        sim.pop(key, None)
    for key in ("nests", "order", "order_seed"):
        doc["plan"].pop(key, None)
    doc["tool"].update(payload_kg=0.0, payload_cog_flange_mm=[0.0, 0.0, 0.0])
    return doc


def small_config(tmp_path: Path, name: str = "irb2600", phenomena: bool = False, **overrides) -> Path:
    """Copy configs/NAME.yaml with a coarser grid (fast) and apply dotted-key overrides; ``phenomena`` False: the
    ``geometric_only`` cell (the demo's effects, lag, drift, nests and random order off). The config's
    ``acceptance`` criterion is for its full plan: left out here unless given as an override."""
    doc = yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())
    doc.pop("acceptance", None)
    if not phenomena:
        doc = geometric_only(doc)
    doc["plan"]["grid"]["step_mm"] = 400
    doc["plan"]["test"]["count"] = 30
    doc["plan"]["check_poses"] = {"count": 3, "every_n_points": 20}
    doc["output"] = {"dir": str(tmp_path / "runs")}
    for key, value in overrides.items():
        node = doc
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    path = tmp_path / f"{name}-small.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


SMALL_ARM_JOINTS = [  # robocal.simulation.truth_cell.small_arm_nominal (the published UR5 DH table)
    {"alpha_deg": 90, "a_mm": 0, "d_mm": 89.159, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360},
    {"alpha_deg": 0, "a_mm": -425, "d_mm": 0, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360},
    {"alpha_deg": 0, "a_mm": -392.25, "d_mm": 0, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360},
    {"alpha_deg": 90, "a_mm": 0, "d_mm": 109.15, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360},
    {"alpha_deg": -90, "a_mm": 0, "d_mm": 94.65, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360},
    {"alpha_deg": 0, "a_mm": 0, "d_mm": 82.3, "theta_deg": 0, "q_min_deg": -360, "q_max_deg": 360}]


def truth_csv(tmp_path: Path, camp, small_arm: bool = False, name: str = "data.csv", **overrides) -> tuple[Path, Path]:
    """A truth campaign (robocal.simulation.truth_cell) as an interchange CSV (read-back joints, rows in measurement order, time and
    payload when logged) and a config of its robot with the nominal SMR offset and no calibration section (only
    the ``calibration.*`` keys given as overrides)."""
    import numpy as np

    from campaign.data.dataset import Dataset
    from campaign.data.interchange_csv import write_csv

    ds = Dataset(camp.point_id, camp.sets, np.degrees(camp.q_read_rad), camp.p_mm, t_s=camp.t_s,
                 payload_kg=camp.payload_kg if np.ptp(camp.payload_kg) > 0 else None)
    csv = tmp_path / name
    write_csv(csv, ds)
    base = "ur10" if small_arm else "irb2600"
    over = {"tool.p_flange_smr_mm": [float(x) for x in camp.nominal.p_flange_smr_mm],
            "tool.payload_kg": float(camp.payload_kg[0]), "robot.repeatability_mm": camp.protocol.repeatability_rp_mm}
    if small_arm:
        over.update({"robot.joints": SMALL_ARM_JOINTS, "robot.hayati_joints": [2, 3]})
    cal = {k: v for k, v in overrides.items() if k.startswith("calibration.")}
    cfg = small_config(tmp_path, base, **{**over, **{k: v for k, v in overrides.items() if k not in cal}})
    doc = yaml.safe_load(cfg.read_text())
    doc.pop("calibration", None)                    # the defaults, unless the caller sets a calibration key
    for key, value in cal.items():
        doc.setdefault("calibration", {})[key.split(".", 1)[1]] = value
    cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
    return csv, cfg


def read_report(directory: Path) -> CalibrationReport:
    """``report.json`` of a run or output directory, as the typed record (RecordError when a field is wrong)."""
    return CalibrationReport.from_dict(json.loads((Path(directory) / "report.json").read_text()))


def read_verify(path: Path) -> VerifyReport:
    """A ``verify.json``, as the typed record."""
    return VerifyReport.from_dict(json.loads(Path(path).read_text()))


def simulated_campaign(cell, seed: int):
    """The cell's plan measured once on its simulated cell (``campaign.config.simulation``): calibration points
    in plan order (noise seed ``seed``), then the test points by id (seed 10 000 + ``seed``), as a Dataset."""
    import numpy as np

    from campaign.config.simulation import simulated_cell
    from campaign.data.dataset import Dataset
    from campaign.plan.build import build_plan

    plan = build_plan(cell)
    cal = [p for p in plan.points if p.set == "calib"]
    test = sorted((p for p in plan.points if p.set == "test"), key=lambda p: p.point_id)
    sim = simulated_cell(cell)
    q_cal, q_test = np.radians([p.q_deg for p in cal]), np.radians([p.q_deg for p in test])
    p_cal, _ = sim.measure(q_cal, np.random.default_rng(seed))
    p_test, _ = sim.measure(q_test, np.random.default_rng(10_000 + seed))
    return Dataset(tuple(f"C{i}" for i in range(len(q_cal))) + tuple(f"T{i}" for i in range(len(q_test))),
                   ("calib",) * len(q_cal) + ("test",) * len(q_test), np.degrees(np.vstack([q_cal, q_test])),
                   np.vstack([p_cal, p_test]), source="simulated")


def layer_kept_without_claim(ds, cell, cell_none, label: str) -> tuple[float, float] | None:
    """When the default calibration of ``ds`` keeps a residual layer without the t > 3 of a claim: the held-out
    RMS (mm) without a layer (``cell_none``: the same config with ``residual: none``) and with it; else None."""
    from campaign.calibrate.stages import calibrate_dataset

    rep = calibrate_dataset(ds, cell).report
    chosen = rep.residual_choice.chosen
    if chosen == "none" or rep.residual_choice.candidates[chosen]["significant"]:
        return None
    without, with_ = calibrate_dataset(ds, cell_none).report.final.test.rms_mm, rep.final.test.rms_mm
    print(f"{label}: {chosen} kept at t {rep.residual_choice.candidates[chosen]['t']:.2f}; held-out RMS without "
          f"{without:.4f} mm, with {with_:.4f} mm")
    return without, with_
