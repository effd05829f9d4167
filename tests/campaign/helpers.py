"""Small configs derived from the shipped ones, for fast campaign tests; the reports a command wrote, typed."""
from __future__ import annotations

import json
from pathlib import Path

import yaml

from campaign.calibrate.calibration_report import CalibrationReport
from campaign.correct.verify_report import VerifyReport

ROOT = Path(__file__).resolve().parents[2]


def small_config(tmp_path: Path, name: str = "irb2600", **overrides) -> Path:
    """Copy configs/NAME.yaml with a coarser grid (fast) and apply dotted-key overrides."""
    doc = yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())
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
