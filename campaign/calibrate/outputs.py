"""The files of a calibration: ``report.json`` and ``model.json`` written, the model read back (correct, verify,
iso9283, export)."""
from __future__ import annotations

import json
from pathlib import Path

from campaign.errors import DataError
from campaign.io.durable import write_json
from robocal.layers.calibrated_model import CalibratedModel

from .stages import Calibrated


def write_outputs(processed: Calibrated, out_dir: str | Path) -> Path:
    """DIR/report.json and DIR/model.json (the calibrated model, plain JSON with units); DIR/points.csv first when
    the report's per-point rows are too many to keep inline (``campaign.calibrate.report_points``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref = processed.report.points
    if isinstance(ref, dict) and "file" in ref:
        processed.points.write_csv(out / ref["file"])
    write_json(out / "report.json", processed.report.to_dict())
    write_json(out / "model.json", processed.model.to_dict())
    return out / "report.json"


RUN_FILES = ("log.jsonl", "data.csv (interchange)")
"""What a run writes before the calibration's outputs (the config copy, plan.csv and campaign.log aside)."""


def output_files(report) -> list[str]:
    """The files a calibration writes into its directory (report.html and its figures by ``write_report``)."""
    ref = report.points
    side = [ref["file"]] if isinstance(ref, dict) and "file" in ref else []
    return ["report.json", "model.json", *side, "report.html", "report_figures/ (PNG)"]


def run_files(report) -> list[str]:
    """The files of a finished calibration run, the log first."""
    return [*RUN_FILES, *output_files(report)]


def load_model(path: str | Path) -> CalibratedModel:
    """Read a model.json written by write_outputs."""
    try:
        return CalibratedModel.from_dict(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(str(path), f"not a readable calibrated model: {exc}") from None
