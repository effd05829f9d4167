"""ISO 9283 characteristics of an acceptance run: AP / RP / AD / RD (``robocal.iso9283``) of the logged cycles,
with nominal and, given a calibrated model, corrected targets, as the run's ``report.json``
(``campaign-iso9283/1``), with the same summary, SIMULATED banner, traceability and verdict as a calibration
report. The cube and its plan are in :mod:`campaign.plan.iso9283`; the run itself is
``campaign.workflows.run_iso9283``.

Rows are logged as set ``check`` (repeated poses) with ids ``N:P3.c07`` (nominal targets) or ``C:P3.c07``
(corrected targets).

Frame: the attained positions are measured in the tracker frame. With a calibrated model its registration
``T_tracker_base`` maps them into the robot base frame (the certificate). Without one, the base frame is the
least-squares rigid fit of the five barycentres onto the commanded poses: RP, RD and AD are unaffected, but AP
then excludes the part of the error a rigid frame absorbs (the report says so).

Repeatability against the datasheet: every pose's measured RP is split into the tracker's contribution (from the
config's ``tracker.uncertainty`` at the pose) and the robot's (``robocal.iso9283.split_rp``: the tracker removed
in quadrature, with a 95 % interval); the verdict (:func:`rp_verdict`) is taken on the robot's RP.
"""
from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from campaign.calibrate.calibration_report import IDENTIFICATION_KEYS
from campaign.calibrate.summary import FAIL, PASS
from campaign.config.cell_model import CellModel
from campaign.errors import DataError
from campaign.plan.iso9283 import IsoCube, iso_cube
from campaign.run.log_records import PointRecord
from robocal.kinematics.frames import fit_rigid, inv_T, transform_points
from robocal.iso9283 import COVERAGE_K, POSE_NAMES, RepeatabilitySplit, characteristics, split_rp

if TYPE_CHECKING:                   # a report of a run needs no model's numerics (nor scipy.optimize) loaded
    from robocal.layers.calibrated_model import CalibratedModel


REPORT_FORMAT = "campaign-iso9283/1"
CALIBRATION_FORMAT = "campaign-report/1"
RUN_PREFIX = "iso9283-"                # RUN/iso9283-TIMESTAMP: an ISO run made with the model of RUN


FRAME_MODEL = "registration of the calibrated model (T_tracker_base)"
FRAME_FIT = ("least-squares rigid fit of the five barycentres to the commanded poses (no model given): AP excludes "
             "the part of the error a rigid frame absorbs; RP, AD and RD are frame-independent")
TRACKER_SOURCE = "the tracker's specifications (tracker.uncertainty) at each pose's distance"
UNDECIDED, NO_SPEC = "undecided", "no datasheet repeatability"
DECISION_RULE = ("the robot's RP of every pose (the tracker's contribution removed in quadrature) against the "
                 f"datasheet RP, with its 95 % interval (the measured RP plus or minus {COVERAGE_K:g} u, u its "
                 "jackknife standard uncertainty over the cycles): PASS when every interval lies at or below the "
                 "datasheet, FAIL when one lies wholly above it, UNDECIDED otherwise (the test cannot tell)")


@dataclass(frozen=True)
class IsoVerdict:
    """The robot's RP against the datasheet (``spec_mm``, None: not set): ``result`` pass | fail | undecided |
    no datasheet repeatability; ``failed`` / ``undecided`` name the poses ("corrected P3") whose interval lies
    wholly above the datasheet / straddles it."""
    spec_mm: float | None
    result: str
    failed: tuple[str, ...] = ()
    undecided: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return asdict(self) | {"failed": list(self.failed), "undecided": list(self.undecided)}


@dataclass(frozen=True)
class ModelRef:
    """The calibrated model an ISO run used: its file, sha256, and the calibration report beside it (relative to
    the ISO run directory; None when the model's directory has none)."""
    path: str
    sha256: str
    calibration_report: str | None

    def to_dict(self) -> dict:
        return asdict(self)


def rp_verdict(splits: Mapping[str, RepeatabilitySplit], spec_mm: float | None) -> IsoVerdict:
    """The verdict of :data:`DECISION_RULE` over the poses' splits (name -> split) against ``spec_mm``."""
    if not spec_mm:
        return IsoVerdict(None, NO_SPEC)
    failed = tuple(name for name, s in splits.items() if s.rp_robot_low_mm > spec_mm)
    undecided = tuple(name for name, s in splits.items() if s.rp_robot_low_mm <= spec_mm < s.rp_robot_high_mm)
    return IsoVerdict(float(spec_mm), FAIL if failed else UNDECIDED if undecided else PASS, failed, undecided)


def calibration_dir(model_path: str | os.PathLike) -> Path | None:
    """The directory of a model written by ``run`` or ``reprocess`` (its calibration ``report.json`` beside it),
    where ISO runs made with the model go by default (``DIR/iso9283-TIMESTAMP``); None otherwise."""
    import json

    d = Path(model_path).resolve().parent
    try:
        return d if json.loads((d / "report.json").read_text()).get("format") == CALIBRATION_FORMAT else None
    except (OSError, ValueError, AttributeError):
        return None


def is_iso_run_of(run_dir: str | os.PathLike, cal_dir: str | os.PathLike) -> bool:
    """True when ``run_dir`` is ``CAL_DIR/iso9283-*``: an ISO run the calibration report of CAL_DIR lists."""
    run_dir = Path(run_dir).resolve()
    return run_dir.parent == Path(cal_dir).resolve() and run_dir.name.startswith(RUN_PREFIX)


def model_ref(model_path: str | os.PathLike, run_dir: str | os.PathLike) -> ModelRef:
    """The model file's reference for the ISO report of ``run_dir``: sha256, and the link to its calibration
    report (``report.html`` beside it) relative to ``run_dir``."""
    path = Path(model_path).resolve()
    html = path.parent / "report.html"
    link = Path(os.path.relpath(html, Path(run_dir).resolve())).as_posix() if html.exists() else None
    return ModelRef(str(path), hashlib.sha256(path.read_bytes()).hexdigest(), link)


def iso_report(cell: CellModel, records: list[PointRecord], cube: IsoCube, model: CalibratedModel | None,
               identification: Mapping | None = None, ref: ModelRef | None = None) -> dict:
    """AP/RP per pose (RP split into the tracker's and the robot's) and AD/RD (P2-P4) of every target kind in the
    log records (``N:`` and ``C:`` ids); the run log's ``identification`` and the model's ``ref`` for the
    traceability."""
    cfg = cell.config
    by_kind: dict[str, dict[str, list]] = {}
    for rec in records:
        kind, rest = rec.point_id.split(":", 1)
        by_kind.setdefault(kind, {}).setdefault(rest.split(".")[0], []).append(rec.p_tracker_mm)
    if "N" not in by_kind:
        raise DataError("iso9283", "the log has no ISO 9283 cycles (point ids N:Pk.cNN)")
    p_cmd = cube.p_base_mm
    if model is not None:
        T_base_tracker, frame = inv_T(model.kinematics.T_tracker_base), FRAME_MODEL
    else:
        bary = np.array([np.mean(by_kind["N"][name], axis=0) for name in POSE_NAMES])
        T_base_tracker, frame = fit_rigid(bary, p_cmd), FRAME_FIT
    runs, splits = [], {}
    for kind, label in (("N", "nominal"), ("C", "corrected")):
        if kind not in by_kind:
            continue
        n = min(len(by_kind[kind][name]) for name in POSE_NAMES)
        p_tracker = np.array([by_kind[kind][name][:n] for name in POSE_NAMES])
        p = np.array([transform_points(T_base_tracker, pt) for pt in p_tracker])
        poses, dist = characteristics(p, p_cmd)
        cov = cell.tracker.covariance(p_tracker.mean(axis=1))                # at each pose, tracker frame
        split = [split_rp(p[j], cov[j]) for j in range(len(POSE_NAMES))]
        splits.update({f"{label} {name}": s for name, s in zip(POSE_NAMES, split)})
        dev = {name: np.round((p[j] - p[j].mean(axis=0)) * 1000.0, 2).tolist() for j, name in enumerate(POSE_NAMES)}
        worst = int(np.argmax([s.rp_robot_mm for s in split]))
        runs.append({"targets": label, "cycles": n,
                     "poses": [pc.to_dict() | s.to_dict() for pc, s in zip(poses, split)],
                     "distance": dist.to_dict(), "max_ap_mm": max(pc.ap_mm for pc in poses),
                     "max_rp_mm": max(pc.rp_mm for pc in poses), "worst_pose": worst,
                     "deviation_um": dev})
    verdict = rp_verdict(splits, cfg.robot.repeatability_mm)
    ident = {k: identification[k] for k in IDENTIFICATION_KEYS if k in (identification or {})}
    T_tb = inv_T(T_base_tracker)
    floor = cell.noise_floor_mm(transform_points(T_tb, p_cmd))
    return {"format": REPORT_FORMAT, "config": cfg.name, "frame": frame,
            "cube": {"center_mm": cube.center_mm.tolist(), "edge_mm": cube.edge_mm, "note": cube.note,
                     "poses_base_mm": p_cmd.tolist()},
            "cycles": cfg.plan.iso9283.cycles, "payload_kg": cfg.tool.payload_kg,
            "noise_floor_mm": floor, "repeatability_spec_mm": cfg.robot.repeatability_mm,
            "tracker_rp_source": TRACKER_SOURCE, "decision_rule": DECISION_RULE,
            "summary": {"simulated_devices": ident.get("simulated_devices"), "verdict": verdict.to_dict()},
            "model": None if ref is None else ref.to_dict(), "T_tracker_base": T_tb.tolist(), "source": "log.jsonl",
            "cell": {"robot_model": cfg.robot.model, "tracker_model": cfg.tracker.model}, "runs": runs} | ident


def finish(cell: CellModel, run_dir, model: CalibratedModel | None = None,
           model_path: str | os.PathLike | None = None) -> dict:
    """After the cycles are measured: the ISO report from the run's log, written as report.json."""
    from campaign.io.durable import write_json
    from campaign.run.log_reader import read_log
    from campaign.run.traceability import identification

    contents = read_log(Path(run_dir))
    records = [p for p in contents.records() if ":" in p.point_id]
    ref = None if model_path is None else model_ref(model_path, run_dir)
    report = iso_report(cell, records, iso_cube(cell), model, identification(contents), ref)
    write_json(Path(run_dir) / "report.json", report)
    return report
