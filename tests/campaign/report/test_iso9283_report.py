"""The ISO 9283 report (issue 24): RP against the datasheet repeatability with pass/fail, units on every column,
µm in the scatter, a 3-D scatter with equal axes and z; terminal at 80 columns."""
import io

import numpy as np
import pytest

from campaign.io.terminal_text import SafeConsole
from campaign.report.iso9283 import rp_within_spec
from campaign.report.terminal import render_iso
from robocal.iso9283 import POSE_NAMES, characteristics


def _iso_report(rp_sigma_mm: float, spec_mm: float) -> dict:
    rng = np.random.default_rng(3)
    p_cmd = rng.uniform(-500, 500, (5, 3)) + [1200, 0, 900]
    p = p_cmd[:, None, :] + 0.02 + rng.normal(0, rp_sigma_mm, (5, 30, 3))
    poses, dist = characteristics(p, p_cmd)
    dev = {n: ((p[j] - p[j].mean(axis=0)) * 1000).tolist() for j, n in enumerate(POSE_NAMES)}
    max_rp = max(pc.rp_mm for pc in poses)
    run = {"targets": "nominal", "cycles": 30, "poses": [pc.to_dict() for pc in poses], "distance": dist.to_dict(),
           "max_ap_mm": max(pc.ap_mm for pc in poses), "max_rp_mm": max_rp,
           "rp_within_spec": rp_within_spec(max_rp, spec_mm), "deviation_um": dev}
    return {"format": "campaign-iso9283/1", "config": "t", "frame": "fit", "runs": [run], "cycles": 30,
            "payload_kg": 5.0, "cube": {"center_mm": [1200, 0, 900], "edge_mm": 600.0, "note": "", "poses_base_mm":
                                         p_cmd.tolist()}, "noise_floor_mm": 0.03, "repeatability_spec_mm": spec_mm}


@pytest.mark.unit
def test_rp_is_compared_with_the_datasheet():
    assert rp_within_spec(0.05, 0.04) is False and rp_within_spec(0.03, 0.04) is True
    assert rp_within_spec(0.03, None) is None


@pytest.mark.unit
@pytest.mark.parametrize("sigma, verdict", [(0.004, "pass"), (0.03, "fail")])
def test_terminal_names_units_and_the_verdict_at_80_columns(sigma, verdict):
    rep = _iso_report(sigma, 0.05)
    console = SafeConsole(width=80, record=True, file=io.StringIO())
    render_iso(console, rep)
    text = console.export_text()
    assert all(len(line) <= 80 for line in text.splitlines())
    for col in ("AP (mm)", "APx (mm)", "APy (mm)", "APz (mm)", "RP (mm)"):
        assert col in text
    flat = " ".join(text.split())
    assert f"vs datasheet repeatability 0.0500 mm (robot.repeatability_mm): {verdict}" in flat
    assert f"RP max {rep['runs'][0]['max_rp_mm']:.4f} mm" in flat


@pytest.mark.unit
def test_html_table_units_verdict_and_3d_scatter(monkeypatch):
    pytest.importorskip("matplotlib")
    from campaign.report import html_figures
    from campaign.report.html import ReportSources, render_html

    rep = _iso_report(0.03, 0.05)
    drawn = []
    monkeypatch.setattr(html_figures, "_png", lambda fig: drawn.append(fig) or b"png")
    figs = html_figures.iso_figures(rep)
    scatter = drawn[-1]
    axes = scatter.axes
    assert len(axes) == 5 and all(ax.name == "3d" for ax in axes)
    for ax in axes:
        lims = {ax.get_xlim(), ax.get_ylim(), ax.get_zlim()}
        assert len(lims) == 1                                    # one scale on x, y and z, and for every pose
        assert "µm" in ax.get_zlabel() and "µm" in ax.get_xlabel()
        assert ax.get_box_aspect() is not None
    assert "µm" in figs[-1].caption
    page = render_html(ReportSources("iso", iso9283=rep), {"calibration": [], "verify": [], "diagnosis": [],
                                                          "iso9283": figs})
    for col in ("APx (mm)", "APy (mm)", "APz (mm)", "RP (mm)", "n (cycles)"):
        assert f">{col}</th>" in page
    assert "(<code>robot.repeatability_mm</code>): <strong>fail</strong>" in page
    assert " um" not in page and "(um)" not in page
