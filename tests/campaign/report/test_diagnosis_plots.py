"""Diagnosis figures (issue 24): with no accepted effect "geometric = final" is one curve titled so, the workspace
map one panel that claims no effect, and no shrinkage chart; with an accepted effect both curves and the chart.
The decision follows the accepted-effects list, not a comparison of the numbers."""
import numpy as np
import pytest

pytest.importorskip("matplotlib")

from campaign.report import diagnosis_plots  # noqa: E402


def _maps(rng, offset: float) -> dict:
    ws = {"radius_edges_mm": [500.0, 900.0, 1300.0], "z_edges_mm": [400.0, 900.0, 1400.0],
          "rms_mm": (0.03 + offset + 0.01 * rng.random((2, 2))).tolist()}
    joints = [{"label": f"J{j + 1} (deg)", "edges": [-60.0, 0.0, 60.0], "rms_mm": [0.03 + offset, None]}
              for j in range(6)]
    return {"workspace": ws, "joints": joints, "time": {"label": "t (min)", "edges": [0.0, 1.0, 2.0],
                                                         "rms_mm": [0.03 + offset, 0.031 + offset]}}


def _report(accepted: bool) -> dict:
    rng = np.random.default_rng(7)
    geometric = _maps(rng, 0.0)
    final = _maps(np.random.default_rng(7), -0.005 if accepted else 1e-12)   # rounding apart when nothing taken
    finding = {"effect": "backlash", "joints": [2], "accepted": accepted, "evidence": {}}
    stages = [{"added": "geometric model", "test_rms_mm": 0.034}]
    if accepted:
        stages.append({"added": "backlash", "test_rms_mm": 0.029})
    return {"noise_floor_mm": 0.028, "noise_floor_source": "repeats", "noise_floor_specs_mm": 0.033, "notes": [],
            "evaluation": "test", "findings": [finding], "stages": stages,
            "maps": {"geometric": geometric, "final": final}}


def _figures(monkeypatch, report, tmp_path):
    """{file name: matplotlib figure} as write_plots draws them."""
    drawn = {}
    monkeypatch.setattr(diagnosis_plots, "_save_png", lambda fig, path: drawn.__setitem__(path.name, fig))
    files = diagnosis_plots.write_plots(report, tmp_path)
    assert [f.name for f in files] == list(drawn)
    return drawn


def _curves(ax) -> list[str]:
    return [line.get_label() for line in ax.get_lines() if not line.get_label().startswith(("noise", "repeat", "_"))]


@pytest.mark.system
def test_no_accepted_effect_draws_geometric_equals_final_once(monkeypatch, tmp_path):
    figs = _figures(monkeypatch, _report(accepted=False), tmp_path)
    assert "shrinkage.png" not in figs
    ws = [ax for ax in figs["where_workspace.png"].axes if ax.get_label() != "<colorbar>"]
    assert len(ws) == 1 and "= final model (no effect accepted)" in ws[0].get_title()
    assert all("with the effects" not in ax.get_title() for ax in ws)
    joints = figs["where_joints.png"]
    assert "geometric = final" in joints._suptitle.get_text()
    assert _curves(joints.axes[0]) == ["geometric = final (no effect accepted)"]
    time_ax = figs["where_time.png"].axes[0]
    assert _curves(time_ax) == ["geometric = final (no effect accepted)"] and "= final" in time_ax.get_title()


@pytest.mark.system
def test_an_accepted_effect_draws_both_curves_and_the_shrinkage(monkeypatch, tmp_path):
    figs = _figures(monkeypatch, _report(accepted=True), tmp_path)
    assert "shrinkage.png" in figs
    ws = [ax for ax in figs["where_workspace.png"].axes if ax.get_label() != "<colorbar>"]
    assert [ax.get_title() for ax in ws] == ["geometric model", "final (geometric + backlash) model"]
    assert _curves(figs["where_joints.png"].axes[0]) == ["geometric", "final (geometric + backlash)"]
