"""Elasto-geometric calibration: physical effects identified with the geometry, selected by CV, used by AP(q)."""
import json

import numpy as np
import pytest

from robocal.effects import apply_effects, gear_cyclic, joint_compliance, lumped_compliance
from robocal.elastic import EffectChoice, calibrate_elastic, candidate_effects, select_effects
from robocal.identify import CalibrationOptions, calibrate
from robocal.kinematics import ParamLayout, smr_tracker
from robocal.model import CalibratedModel
from robocal.noise import TrackerUncertainty
from robocal.simulate import random_geometric_errors
from tests.cells import T_SEED000, irb2600

LO, HI = np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180])


def campaign(seed, effects, n=260, payload_kg=10.0):
    rng = np.random.default_rng(seed)
    nominal = irb2600()
    truth = random_geometric_errors(nominal, rng).with_(T_tracker_base=T_SEED000)
    q = rng.uniform(LO, HI, (n, 6))
    meta = {"payload_kg": np.full(n, payload_kg)}
    p = apply_effects(truth, q, meta, effects)
    cov = TrackerUncertainty().covariance(p)
    p = p + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal(p.shape))
    return nominal, truth, q, p, cov, meta


def fit(nominal, q, p, cov, meta, sl):
    geo = calibrate(nominal, q[sl], p[sl], cov[sl], CalibrationOptions(method="lm"))
    cols = np.array([ParamLayout.of(nominal).index(n) for n in geo.identified])
    sub = {k: v[sl] for k, v in meta.items()}
    sel = select_effects(geo.kinematics, cols, q[sl], p[sl], cov[sl], sub, candidate_effects(geo.kinematics, q[sl], sub))
    return geo, cols, sel, sub


def rms(e):
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


@pytest.mark.unit
def test_compliance_of_another_functional_form_is_selected_and_used_by_the_model():
    """Truth: lumped-mass compliance with off-line centres of mass and an offset payload (not the candidate's own
    form) + a gear harmonic on J1; the model takes compliance (and the harmonic), and its test error approaches
    the noise while the geometric model's does not."""
    truth_effects = [(lumped_compliance((2, 3), (0, 30, 45, 10, 5, 1), 0.4, 40.0, (0, 0, 120.0)), np.array([1.5e-6, 2.5e-6])),
                     (gear_cyclic(1, (1,)), np.array([1.2e-4, -0.8e-4]))]
    nominal, truth, q, p, cov, meta = campaign(3, truth_effects)
    cal, test = slice(0, 200), slice(200, None)
    geo, cols, sel, sub = fit(nominal, q, p, cov, meta, cal)
    taken = [c.label for c in sel.taken]
    print("taken", taken, {t.label: round(t.gain, 3) for t in sel.trials if t.round == 1})
    assert taken[0] == "joint_compliance(J2,3)" and "gear_cyclic(J1)" in taken
    el = calibrate_elastic(geo.kinematics, cols, q[cal], p[cal], cov[cal], sub, sel.taken)
    model = CalibratedModel(el.kinematics, None, None, el.effects, 10.0)
    floor = float(np.sqrt(np.mean(np.trace(cov[test], axis1=1, axis2=2))))
    e_geo, e_el = rms(p[test] - smr_tracker(geo.kinematics, q[test])), rms(p[test] - model.smr_tracker(q[test]))
    print(f"test RMS geometric {e_geo:.4f}, elasto-geometric {e_el:.4f}, floor {floor:.4f} mm")
    assert e_el < 1.3 * floor < 0.5 * e_geo
    again = CalibratedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    assert np.allclose(again.smr_tracker(q[test]), model.smr_tracker(q[test]), atol=1e-9)
    comp = model.to_dict()["effects"][0]["params"]
    assert comp["c2"]["unit"] == "rad/(N*m)" and comp["c2"]["stiffness_Nm_per_rad"] == pytest.approx(1 / comp["c2"]["value"])


@pytest.mark.unit
def test_no_effect_is_taken_on_geometric_only_data():
    for seed in range(5):
        nominal, truth, q, p, cov, meta = campaign(20 + seed, [], n=150)
        _, _, sel, _ = fit(nominal, q, p, cov, meta, slice(None))
        assert sel.taken == (), [c.label for c in sel.taken]
        assert len({t.label for t in sel.trials}) >= 8


@pytest.mark.unit
def test_identifiability_reports_an_effect_parameter_the_poses_cannot_separate():
    """J1 gear harmonic with J1 fixed: its columns are constant, redundant with the base registration."""
    nominal, truth, q, p, cov, meta = campaign(5, [(joint_compliance((2, 3)), np.array([1e-6, 2e-6]))], n=120)
    q[:, 0] = 0.3
    p = apply_effects(truth, q, meta, [(joint_compliance((2, 3)), np.array([1e-6, 2e-6]))])
    geo = calibrate(nominal, q, p, None, CalibrationOptions(method="lm"))
    cols = np.array([ParamLayout.of(nominal).index(n) for n in geo.identified])
    el = calibrate_elastic(geo.kinematics, cols, q, p, None, meta,
                           [EffectChoice("joint_compliance", (("joints", (2, 3)),)), EffectChoice("gear_cyclic", (("joint", 1),))])
    names = {u.name for u in el.unidentifiable}
    assert {"gear_cyclic(J1).sin1", "gear_cyclic(J1).cos1"} & names
    assert el.effects[0].values[0] == pytest.approx(1e-6, rel=0.05)
