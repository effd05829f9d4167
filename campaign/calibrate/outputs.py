"""The files of a calibration: ``report.json``, ``model.json`` and ``effects.yaml`` written, the model read back
(correct, verify, iso9283, export)."""
from __future__ import annotations

import json
from pathlib import Path

import yaml

from campaign.errors import DataError
from campaign.io.durable import atomic_write, write_json
from robocal.layers.calibrated_model import CalibratedModel

from .stages import Calibrated


EFFECTS_FILE = "effects.yaml"
EFFECTS_HEADER = """\
# The physical effects of this calibration's model (chosen by calibration.effects: auto, or configured).
# A shorter campaign of the same robot (a recalibration from 50 poses, say) can fit these effects instead of
# choosing them from its few poses, which often cannot show every effect a full campaign found: put the
# `effects:` list below under `calibration:` in that campaign's config.
"""


def write_outputs(processed: Calibrated, out_dir: str | Path) -> Path:
    """DIR/report.json and DIR/model.json (the calibrated model, plain JSON with units); DIR/points.csv first when
    the report's per-point rows are too many to keep inline (``campaign.calibrate.report_points``); DIR/effects.yaml
    when the model has physical effects (``effects_yaml``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref = processed.report.points
    if isinstance(ref, dict) and "file" in ref:
        processed.points.write_csv(out / ref["file"])
    write_json(out / "report.json", processed.report.to_dict())
    write_json(out / "model.json", processed.model.to_dict())
    if processed.model.effects:
        atomic_write(out / EFFECTS_FILE, effects_yaml(processed.model).encode())
    return out / "report.json"


def effects_yaml(model: CalibratedModel) -> str:
    """The model's physical effects as the ``calibration.effects`` section of a cell's config (YAML text with
    ``EFFECTS_HEADER``): a campaign configured with it fits the same effects (its values anew)."""
    items = [fe.choice.to_spec() for fe in model.effects]
    return EFFECTS_HEADER + yaml.safe_dump({"calibration": {"effects": items}}, sort_keys=False,
                                           default_flow_style=None)


RUN_FILES = ("log.jsonl", "data.csv (interchange)")
"""What a run writes before the calibration's outputs (the config copy, plan.csv and campaign.log aside)."""


def output_files(processed: Calibrated) -> list[str]:
    """The files a calibration writes into its directory (report.html and its figures by ``write_report``)."""
    ref = processed.report.points
    side = [ref["file"]] if isinstance(ref, dict) and "file" in ref else []
    side += [EFFECTS_FILE] if processed.model.effects else []          # the model's, not the report's effects
    return ["report.json", "model.json", *side, "report.html", "report_figures/ (PNG)"]


def run_files(processed: Calibrated) -> list[str]:
    """The files of a finished calibration run, the log first."""
    return [*RUN_FILES, *output_files(processed)]


def load_model(path: str | Path) -> CalibratedModel:
    """Read a model.json written by write_outputs."""
    try:
        return CalibratedModel.from_dict(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(str(path), f"not a readable calibrated model: {exc}") from None
