"""The terminal's physical-effects lines state the selection's two paths when it compared them (issue 32's
twentieth protocol, ``robocal.effects.select.LINKS_PATH_GAIN``)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
from rich.console import Console

from campaign.report.terminal import render_choices

pytestmark = pytest.mark.unit


def _report(path: str | None):
    trial = {"effect": "joint_compliance(J2,3 links)", "candidate": "joint_compliance(J2,3 links)",
             "cv_rms_mm": 0.0479, "taken": True}
    sel = {"trials": [trial], "geometric_cv_rms_mm": 0.2, **({"path": path} if path else {})}
    effects = SimpleNamespace(selection=sel, counts=SimpleNamespace(taken=1, tried=1), fitted=(), notes=())
    return SimpleNamespace(effects=effects, residual_choice=None, excluded_points=(), structure_note="",
                           multi_smr=None)


@pytest.mark.parametrize("path", [None, "the links' form offered in place of the lever form: final held-out RMS "
                                        "0.0479 mm, the lever form's path 0.0995 mm; kept the links' path"])
def test_the_two_paths_are_stated_when_compared(path):
    console = Console(record=True, width=200)
    render_choices(console, _report(path))
    text = console.export_text()
    assert ("two paths: " + path in text) if path else "two paths" not in text
    assert "1 of 1 candidates taken" in text
