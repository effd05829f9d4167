"""Regression pin of the diagnosis on one seeded synthetic campaign: the figures below were produced by the
single-module diagnosis before it was split into the ``robocal.diagnose`` package, so a change of behaviour
in the restructured code (or later) shows here. Plus: thresholds moved into ``DiagnosisOptions`` are wired."""
from dataclasses import replace

import pytest

from robocal.diagnose import DiagnosisOptions, diagnose
from robocal.selfcheck import simulate_campaign

REL = 1e-6          # pinned to well below any physical meaning; loose enough for another BLAS build


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(["backlash", "thermal_drift"], 7, magnitude=1.0)


@pytest.mark.unit
def test_pinned_diagnosis_of_a_seeded_campaign(campaign):
    d = diagnose(campaign.diagnosis_input())
    assert d.noise_floor_mm == pytest.approx(0.02936466352557628, rel=REL)
    assert d.baseline_test_rms_mm == pytest.approx(0.18159214426429246, rel=REL)
    assert d.final_test_rms_mm == pytest.approx(0.032461509674445096, rel=REL)
    assert not d.unexplained
    acc = [(f.effect, f.joints) for f in d.findings if f.accepted]
    assert acc == [("backlash", (1,)), ("thermal_drift", (1, 2))]
    bic = [f.evidence["delta_bic"] for f in d.findings if f.accepted]
    assert bic == pytest.approx([-1544.9982955989287, -1723.6634333943186], rel=REL)
    assert [s["test_rms_mm"] for s in d.stages] == pytest.approx(
        [0.18159214426429246, 0.09345382811159504, 0.032461509674445096], rel=REL)
    assert [s["cv_rms_mm"] for s in d.stages] == pytest.approx(
        [0.1792241803742099, 0.08035299029057001, 0.03189313687546082], rel=REL)
    assert d.structure["chi2_per_dof"] == pytest.approx(1.1429902459517332, rel=REL)
    assert [f.effect for f in d.findings] == [
        "backlash", "thermal_drift", "axis_coupling", "payload_deflection", "gear_cyclic", "registration_drift",
        "gear_cyclic", "gear_cyclic", "gear_cyclic", "gear_cyclic", "gear_cyclic", "readback_lag",
        "joint_compliance"]
    assert [r.region for r in d.where][:2] == ["all evaluated points",
                                                "J1 approach direction (+ vs -), shift +0.274 mm"]


@pytest.mark.unit
def test_thresholds_of_the_metadata_checks_come_from_the_options(campaign):
    inp = replace(campaign.diagnosis_input(), approach=None)      # fast: one effect less to select
    d = diagnose(inp, DiagnosisOptions(time_min_span_s=1e9, gear_min_span_deg=1e3, max_effects=1))
    reasons = {u["effect"]: u["reason"] for u in d.undiagnosable}
    assert "too short to reveal drift" in reasons["thermal_drift"]
    assert "cannot be told from its zero offset" in reasons["gear_cyclic"]

