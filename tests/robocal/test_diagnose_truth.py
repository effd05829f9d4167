"""Diagnosis on campaigns from the independent truth generator (robocal/truth.py, written from the physics, not
from the candidates): read-back lag vs backlash (10 seeds each), gravity compliance with a q3-dependent J2 torque
vs a J2 gear harmonic, effect-free controls, reference nests with and without timestamps, the direct comparison
of commanded and read-back joints, and a reduced self-check (the full one: `campaign diagnose --self-check`)."""
import ast
from pathlib import Path

import numpy as np
import pytest

from robocal.diagnose import NestReadings, diagnose, nest_drift
from robocal.selfcheck import run_self_check, truth_input
from robocal.truth import TruthProtocol, gravity_torque_nm, random_mass_model, simulate

SMALL = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4, timestamps=False)


def accepted(d):
    return {f.effect: f for f in d.findings if f.accepted}


@pytest.mark.unit
def test_truth_generator_is_independent_of_the_candidate_code():
    tree = ast.parse((Path(__file__).resolve().parents[2] / "robocal" / "truth.py").read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not imported & {"diagnose", "effects", "selfcheck"}, imported


@pytest.mark.unit
def test_truth_gravity_torque_on_j2_depends_on_q3():
    camp = simulate([], 1, SMALL)
    mm = random_mass_model(camp.truth_kin, np.random.default_rng(0))
    q = np.zeros((2, 6))
    q[:, 1] = 0.3
    q[1, 2] = 0.8
    tau = gravity_torque_nm(camp.truth_kin, q, mm, np.zeros(2))
    assert abs(tau[0, 1] - tau[1, 1]) > 0.05 * abs(tau[0, 1])


@pytest.mark.system
@pytest.mark.parametrize("truth,other", [("readback_lag", "backlash"), ("backlash", "readback_lag")])
def test_readback_lag_and_backlash_are_told_apart_on_ten_seeds(truth, other):
    """Random move order, read-back joints only (no commanded joints): the saturation test decides."""
    right = 0
    for seed in range(10):
        camp = simulate([truth], 300 + seed, SMALL)
        d = diagnose(truth_input(camp))
        acc = accepted(d)
        ok = truth in acc and other not in acc
        right += ok
        if not ok:
            print(seed, camp.truths, {k: f.joints for k, f in acc.items()})
        if truth in acc and truth == "readback_lag":
            true_lag = camp.truths[0].values["lag_per_move"]
            got = acc[truth].evidence["lag_deg_per_deg"]
            for j, lam in true_lag.items():
                assert got[f"J{j}"] == pytest.approx(lam, abs=0.3 * abs(lam) + 5e-5)
    assert right == 10


@pytest.mark.system
def test_commanded_joints_measure_the_lag_directly():
    camp = simulate(["readback_lag"], 321, SMALL)
    d = diagnose(truth_input(camp, with_qc=True))
    f = accepted(d)["readback_lag"]
    direct = f.evidence["direct_comparison"]
    for j, lam in camp.truths[0].values["lag_per_move"].items():
        assert direct[f"J{j}"]["lag_deg_per_deg"] == pytest.approx(lam, rel=0.05, abs=2e-6)
        assert direct[f"J{j}"]["t"] * np.sign(lam) > 5
    # without a lag the direct comparison vetoes the candidate, whatever the fit says
    d0 = diagnose(truth_input(simulate(["backlash"], 322, SMALL), with_qc=True))
    lag = next(f for f in d0.findings if f.effect == "readback_lag")
    assert not lag.accepted and "commanded and read-back joints agree" in lag.evidence["reason"]


@pytest.mark.system
def test_gravity_compliance_with_q3_dependent_torque_is_not_called_a_j2_gear_error():
    for seed in (401, 402, 403):
        camp = simulate(["joint_compliance"], seed, SMALL)
        d = diagnose(truth_input(camp))
        acc = accepted(d)
        first = next(f for f in d.findings if f.accepted)
        classes = {first.effect} | {c["effect"] for c in first.evidence.get("confusable_with", [])}
        assert "joint_compliance" in classes, (seed, list(acc))
        gear2 = [f for f in d.findings if f.accepted and f.effect == "gear_cyclic" and 2 in f.joints]
        assert not gear2 or "joint_compliance" in {c["effect"] for c in gear2[0].evidence.get("confusable_with", [])}
        phys = {k: v for k, v in acc["joint_compliance"].evidence["physical"].items() if k.startswith("J")}
        assert acc["joint_compliance"].evidence["physical"]["nested_test"]["delta_bic_given_payload_deflection"] < -10
        k_true = camp.truths[0].values["stiffness_nm_per_rad"]
        assert all(v["stiffness_nm_per_rad"] > 0 for v in phys.values())
        assert set(phys) <= {"J2", "J3"} and k_true


@pytest.mark.system
def test_effect_free_controls_accept_nothing():
    for seed in (501, 502, 503):
        d = diagnose(truth_input(simulate([], seed, SMALL), with_qc=seed % 2 == 0))
        assert not accepted(d), (seed, list(accepted(d)))
        assert d.final_test_rms_mm == d.baseline_test_rms_mm


@pytest.mark.system
def test_reference_nests_rule_drift_out_or_see_it_without_timestamps():
    pr = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4, timestamps=False, nest_every=10)
    stable = simulate([], 601, pr)
    d = diagnose(truth_input(stable))
    reg = next(f for f in d.findings if f.effect == "registration_drift")
    assert "ruled out by the reference nests" in reg.evidence["reason"] and reg.evidence["diagnosable"]
    assert any("reference nests" in n for n in d.notes)
    drifting = simulate(["registration_drift"], 602, pr)
    nd = nest_drift(NestReadings(drifting.nest_p_mm, drifting.nest_id, None, drifting.nest_after_row + 0.5),
                    0.03)
    assert nd["detected"] and nd["basis"] == "measurement order" and nd["drift_mm"] > 0.02
    d2 = diagnose(truth_input(drifting))
    reg2 = next(f for f in d2.findings if f.effect == "registration_drift")
    assert reg2.evidence["nest_drift"]["detected"]


@pytest.mark.system
def test_reduced_self_check_meets_the_targets():
    """One seed per effect, 3 controls, 2 two-effect cases, 1 out-of-library case (the full run: bench)."""
    result = run_self_check(seeds=1, controls=3, combos=2, outside=1)
    s = result.summary()
    print(s)
    assert s["single_trials"] == 8
    assert s["named_right"] >= 7
    assert s["controls_clean"] == s["controls"] == 3
    assert s["spurious_acceptances"] <= 1
    assert s["shrinkage_error_mm"]["mean_abs"] < 0.05


@pytest.mark.system
def test_compliance_and_j2_gear_are_one_class_when_the_data_cannot_separate_them():
    """J3 held at one angle and one payload: the J2 gravity torque is a pure function of q2, like a J2 harmonic.
    Whichever is named first, the other is in its class, with the experiment that would separate them."""
    pr = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4, timestamps=False, q3_fixed_deg=-30.0,
                       compliance_joints=(2,), payloads_kg=(0.0,))
    for seed in (700, 701):
        d = diagnose(truth_input(simulate(["joint_compliance"], seed, pr)))
        first = next(f for f in d.findings if f.accepted)
        assert {first.effect} | {c["effect"] for c in first.evidence["confusable_with"]} >= {"joint_compliance",
                                                                                               "gear_cyclic"}
        assert "equal q2 and different q3" in first.evidence["experiment"]
