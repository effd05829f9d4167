"""Diagnosis on top of the engine: the JSON contract, what cannot be told (measurement order unknown, an order that
follows a joint), the unexplained structure (one definition), evidence that never vetoes, and the building blocks
(structure test, where-analysis)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from robocal.diagnose.core import diagnose
from robocal.diagnose.regions import structure_test, where_analysis
from robocal.diagnose.evidence import follows_order, rival_class
from robocal.effects.model import EffectChoice
from robocal.effects.select import Step
from robocal.diagnose.selfcheck import truth_input
from robocal.simulation.truth_cell import TruthProtocol, simulate

SMALL = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4)
CONTRACT = ["noise_floor_mm", "noise_floor_source", "baseline_test_rms_mm", "final_test_rms_mm", "unexplained",
            "findings", "where"]


def accepted(d):
    return [f for f in d.findings if f.accepted]


@pytest.mark.system
def test_contract_and_one_finding_per_candidate_or_reason():
    d = diagnose(truth_input(simulate(["backlash"], 11, SMALL)))
    out = d.to_dict()
    assert list(out)[:7] == CONTRACT
    acc = accepted(d)
    assert [f.effect for f in acc] == ["backlash"] and acc[0].test_rms_after_mm < acc[0].test_rms_before_mm
    ev = acc[0].evidence
    assert ev["cv_rms_after_mm"] < ev["cv_rms_before_mm"] and ev["plausible"] and "half_width_arcmin" in ev["physical"]
    assert all(f.evidence.get("reason") for f in d.findings if not f.accepted)
    assert [fe.choice.label for fe in d.effects] == [ev["label"]]
    assert d.stages[-1]["test_rms_mm"] == d.final_test_rms_mm


@pytest.mark.system
def test_without_measurement_order_lag_backlash_and_drift_are_cannot_tell_not_a_crash():
    inp = truth_input(simulate(["readback_lag"], 12, replace(SMALL, timestamps=False)))
    d = diagnose(replace(inp, order=None, approach=None, move_rad=None, prev_move_rad=None))
    why = {u["effect"]: u["reason"] for u in d.undiagnosable}
    assert "no measurement order" in why["readback_lag"] and "no measurement order" in why["backlash"]
    assert "no timestamps and no measurement order" in why["registration_drift"]
    assert not any(f.effect in ("readback_lag", "backlash") for f in accepted(d))
    assert all(u["remedy"] for u in d.undiagnosable)


@pytest.mark.system
def test_an_order_that_follows_j1_makes_drift_and_j1_effects_one_class():
    d = diagnose(truth_input(simulate(["gear_cyclic"], 13, replace(SMALL, order="sweep_j1", timestamps=False,
                                                                  gear_joints=(1,)))))
    conf = [u for u in d.undiagnosable if u["effect"] == "registration_drift" and "follows the measurement order" in
            u["reason"]]
    assert conf and conf[0]["joints"] == [1] and "random order" in conf[0]["remedy"]
    acc = accepted(d)
    assert acc and acc[0].effect == "gear_cyclic"
    assert "order_confound" in acc[0].evidence and "registration_drift" in acc[0].evidence["class"]


@pytest.mark.unit
def test_follows_order_separates_a_sweep_from_a_random_order():
    rng = np.random.default_rng(3)
    q1 = rng.uniform(-2, 2, 400)
    assert follows_order(np.sin(q1), np.argsort(np.argsort(q1))) > 0.95
    assert follows_order(np.sin(q1), np.arange(400)) < 0.5


@pytest.mark.system
def test_unexplained_structure_has_one_definition_and_a_layer_removes_an_effect_outside_the_library():
    d = diagnose(truth_input(simulate(["reach_deflection"], 14, SMALL, scale=3.0)))
    u = d.unexplained_structure
    assert u["excess_over_floor_mm"] == pytest.approx(math.sqrt(max(u["heldout_rms_mm"] ** 2 - u["floor_mm"] ** 2, 0)))
    assert u["heldout_rms_mm"] == pytest.approx(d.final_test_rms_mm)
    assert u["layer_removes_mm"] == pytest.approx(math.sqrt(max(u["heldout_rms_mm"] ** 2
                                                                - u["layer_heldout_rms_mm"] ** 2, 0)))
    assert f"{u['excess_over_floor_mm']:.3f} mm" in u["text"] and f"{u['layer_removes_mm']:.3f} mm" in u["text"]
    assert d.unexplained == u["unexplained"] and d.to_dict()["unexplained_structure"]["text"] == u["text"]
    for f in accepted(d):                # whatever stands in for the sag is described, never silently dropped
        assert f.evidence["cv_rms_after_mm"] < f.evidence["cv_rms_before_mm"]


@pytest.mark.system
def test_an_effect_outside_its_physical_range_is_the_best_available_description():
    """A J1 gear term ten times larger than any gear: accepted (it predicts held-out points), described with its
    value outside the range and what to check."""
    pr = replace(SMALL, gear_joints=(1,), gear_arcsec=600.0)
    d = diagnose(truth_input(simulate(["gear_cyclic"], 15, pr)))
    f = accepted(d)[0]
    assert f.effect == "gear_cyclic" and not f.evidence["plausible"]
    assert f.evidence["description"].startswith("best available description: gear_cyclic(J1")
    assert "outside the physical range" in f.evidence["description"]


@pytest.mark.unit
def test_structure_test_separates_noise_from_a_smooth_field():
    rng = np.random.default_rng(2)
    x = rng.uniform(0, 1, (400, 2))
    w = rng.normal(size=(400, 3))
    res = structure_test(w, {"x": x}, np.random.default_rng(0))
    assert abs(res["x"]["z"]) < 3
    field = np.stack([np.sin(6 * x[:, 0]), np.cos(5 * x[:, 1]), x[:, 0]], axis=1)
    res = structure_test(w + 1.5 * field, {"x": x}, np.random.default_rng(0))
    assert res["x"]["z"] > 6 and res["x"]["S"] > 0.5


@pytest.mark.unit
def test_where_names_the_far_reach_region_in_words():
    rng = np.random.default_rng(3)
    m = 300
    radius = rng.uniform(500, 1600, m)
    az = rng.uniform(-1, 1, m)
    p_base = np.stack([radius * np.cos(az), radius * np.sin(az), rng.uniform(300, 1500, m)], axis=1)
    cov = np.broadcast_to(np.eye(3) * 0.015**2, (m, 3, 3)).copy()
    r = rng.normal(0, 0.015, (m, 3))
    far = radius > np.quantile(radius, 2 / 3)
    r[far] += rng.normal(0, 0.08, (far.sum(), 3))
    regions, maps = where_analysis("geometric", r, cov, p_base, rng.uniform(-1, 1, (m, 6)), np.eye(4))
    text = [g.description for g in regions]
    assert any(t.startswith("far reach (radius >") and "vs floor" in t for t in text)
    assert not any(t.startswith("near reach") for t in text)
    assert len(maps["joints"]) == 6 and maps["workspace"]["n"]


@pytest.mark.unit
def test_a_rival_that_a_later_step_took_or_rivalled_is_not_in_the_class_of_the_first():
    """Round 1 takes a J1 order-13 error before compliance and a J2 first harmonic (as good); round 2 takes the J2
    harmonic, with compliance its rival. The model holds both structures: compliance is the J2 harmonic's class,
    not the J1 error's (the public UR5 campaign's case)."""
    j1 = EffectChoice("gear_cyclic", (("joint", 1), ("harmonics", (13,))))
    j2 = EffectChoice("gear_cyclic", (("joint", 2), ("harmonics", (1,))))
    comp = ("joint_compliance(J2,3)", "joint_compliance", 0.108, 1.2)
    first = Step(j1, 1, 0.119, 0.107, {}, 13.5, 0.10, [comp, (j2.label, "gear_cyclic", 0.107, 1.2)])
    second = Step(j2, 2, 0.107, 0.095, {}, 14.1, 0.11, [comp])
    assert [x["label"] for x in rival_class(first)] == ["joint_compliance(J2,3)"]       # alone, as before
    assert rival_class(first, [second]) == []
    assert [x["label"] for x in rival_class(second)] == ["joint_compliance(J2,3)"]
