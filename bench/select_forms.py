"""The measured campaigns the selection benches judge on: the public UR5 campaign (here) and the simulated forms of
issue 32's protocol (``tests/campaign/adaptive_forms.py``, shared with its seeded test)."""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from campaign.config.load import load_cell  # noqa: E402
from tests.campaign.adaptive_forms import ADAPTIVE_FORMS  # noqa: E402,F401

UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"


def ur5_dataset(tmp: Path | None = None):
    """The public UR5 campaign: 1000 grid calibration rows, 20 random held-out poses (configs/ur5.yaml)."""
    from campaign.data.importers import import_target_dif
    return (import_target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                              UR5 / "3D_UR5_uncalibrated_random_cleaned.csv"), load_cell(ROOT / "configs/ur5.yaml"))
