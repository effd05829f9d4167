"""Regression pin of the diagnosis on one seeded truth campaign (robocal/simulation/truth_cell.py: backlash and a warm-up, random
measurement order, timestamps): the accepted effects, their values, the step-by-step figures and the leftover.
Re-pinned when the one effect engine replaced the diagnosis's own selection (issue 20): a change of behaviour
shows here. The cross-validated figures re-pinned when its folds' ridge became rank_tol^2 (issue 32's fifteenth
protocol: they moved by 2e-6 relative; nothing else did). Plus: options reach the engine."""
from dataclasses import replace

import pytest

from robocal.diagnose.records import DiagnosisOptions
from robocal.diagnose.core import diagnose
from robocal.effects.engine import EngineOptions
from robocal.diagnose.selfcheck import truth_input
from robocal.simulation.truth_cell import TruthProtocol, simulate

REL = 1e-6          # pinned to well below any physical meaning; loose enough for another BLAS build


@pytest.fixture(scope="module")
def inp():
    return truth_input(simulate(["backlash", "thermal_drift"], 7, TruthProtocol(), scale=1.0))


@pytest.mark.system
def test_pinned_diagnosis_of_a_seeded_campaign(inp):
    d = diagnose(inp)
    assert d.noise_floor_mm == pytest.approx(0.03501232888463415, rel=REL)
    assert d.baseline_test_rms_mm == pytest.approx(0.42024739686515966, rel=REL)
    assert d.final_test_rms_mm == pytest.approx(0.03664174366486503, rel=REL)
    assert not d.unexplained
    assert [(fe.choice.label, f.joints) for fe, f in zip(d.effects, d.findings)] == [
        ("backlash(J1,2,3)", (1, 2, 3)), ("thermal_drift(J2,3 tau 0.5 h)", (2, 3))]
    assert list(d.effects[0].values) == pytest.approx(
        [-0.00045096855810094593, -0.0004679755006868106, -0.00055409079855558], rel=REL)
    assert list(d.effects[1].values) == pytest.approx(
        [0.00011978264600317336, 0.000202041674043147, 0.00013317991991524395], rel=REL)
    assert [s["test_rms_mm"] for s in d.stages] == pytest.approx(
        [0.42024739686515966, 0.10951008314970732, 0.03664174366486503], rel=REL)
    assert [s["cv_rms_mm"] for s in d.stages] == pytest.approx(
        [0.43218960757137687, 0.1058076956597369, 0.03661517274416571], rel=REL)
    assert d.unexplained_structure["excess_over_floor_mm"] == pytest.approx(0.010805285969186073, rel=REL)
    assert d.unexplained_structure["layer_heldout_rms_mm"] == pytest.approx(0.0365647921898064, rel=1e-4)
    assert [r.region for r in d.where][:2] == ["all evaluated points",
                                                "J2 approach direction (+ vs -), shift -0.415 mm"]


@pytest.mark.system
def test_options_reach_the_engine(inp):
    d = diagnose(replace(inp, t_s=None), DiagnosisOptions(engine=EngineOptions(max_effects=1)))
    assert len([f for f in d.findings if f.accepted]) == 1
    reasons = {u["effect"]: u["reason"] for u in d.undiagnosable}
    assert "no timestamps" in reasons["thermal_drift"]
