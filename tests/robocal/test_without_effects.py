"""The geometric model's trend + GPR layer against a model with physical effects (robocal.layers.choice,
``GEOMETRIC_RIVAL``): chosen when the effects only mimic a smooth field, not when they are the robot's. Independent
references: data written from the geometry, a quadratic sag and a cyclic joint error term by term."""
import numpy as np
import pytest

import robocal.layers.choice as choice
from robocal.effects.model import EffectChoice, FittedEffect
from robocal.kinematics.frames import transform_points
from robocal.layers.calibrated_model import CalibratedModel
from tests.cells import irb2600

LO, HI = np.radians([-60, -40, -60, -90, -60, -90]), np.radians([60, 60, 30, 90, 60, 90])
NOISE_AXIS_MM = 0.01
CYCLIC = EffectChoice("gear_cyclic", (("joint", 1), ("harmonics", (7,))))


def _models():
    """(geometric model, the same with a 7th-harmonic cyclic error of J1, 0.2 mrad amplitude)."""
    kin = irb2600()
    eff = CYCLIC.build(kin.n)
    fe = FittedEffect(CYCLIC, np.array([2e-4, 0.0]), np.full(2, 1e-6), eff.param_names, eff.unit)
    return CalibratedModel(kin), CalibratedModel(kin, None, None, (fe,))


def _sag_mm(p_base_mm):
    """A sag along base z with the square of the horizontal reach (0.3 mm/m^2), a shear of x with z (N, 3) mm."""
    r_m = np.hypot(p_base_mm[:, 0], p_base_mm[:, 1]) / 1000.0
    out = np.zeros_like(p_base_mm)
    out[:, 2] = -0.3 * r_m**2
    out[:, 0] = 0.1 * p_base_mm[:, 2] / 1000.0
    return out


def _measured(model, q, sag: bool, seed: int):
    """Tracker positions (N, 3) mm of ``model`` at q, with the sag when asked, and noise."""
    p = model.kinematic_smr_base(q)
    p = p + (_sag_mm(p) if sag else 0.0) + np.random.default_rng(seed).normal(0, NOISE_AXIS_MM, p.shape)
    return transform_points(model.kinematics.T_tracker_base, p)


def _choose(elastic, geometric, q, p, **kw):
    return choice.choose_layer(elastic, q, p, noise_floor_mm=np.sqrt(3) * NOISE_AXIS_MM, geometric=geometric, **kw)


@pytest.mark.unit
def test_effects_that_only_mimic_a_sag_are_left_out():
    """The robot sags and has no cyclic error: the model that took one predicts worse than the geometry with a
    trend; the final layer sits on the geometry and predicts new poses near the noise."""
    geometric, elastic = _models()
    rng = np.random.default_rng(4)
    q, qt = rng.uniform(LO, HI, (80, 6)), rng.uniform(LO, HI, (40, 6))
    ch = _choose(elastic, geometric, q, _measured(geometric, q, True, 5), candidates=("gpr", "trend_gpr"))
    w = ch.without_effects
    assert ch.on_geometry and ch.kind == "trend_gpr" and w.effects == (CYCLIC.label,)
    assert w.t > 1 and w.cv_rms_mm < 0.98 * w.cv_rms_with_effects_mm and ch.cv_rms_mm == w.cv_rms_mm
    p_true = geometric.kinematic_smr_base(qt)
    p_true = p_true + _sag_mm(p_true)
    final = CalibratedModel(geometric.kinematics, ch.layer)
    err = np.linalg.norm(final.smr_base(qt) - p_true, axis=1)
    assert np.sqrt(np.mean(err**2)) < 3 * np.sqrt(3) * NOISE_AXIS_MM


@pytest.mark.unit
def test_effects_the_robot_has_are_kept():
    """The robot has the cyclic error and no sag: the geometry's trend cannot carry it; the rival is reported and
    not chosen."""
    geometric, elastic = _models()
    q = np.random.default_rng(6).uniform(LO, HI, (80, 6))
    ch = _choose(elastic, geometric, q, _measured(elastic, q, False, 7), candidates=("trend_gpr",))
    w = ch.without_effects
    assert not ch.on_geometry and not w.chosen and w.cv_rms_mm > w.cv_rms_with_effects_mm
    assert ch.to_dict()["without_effects"]["chosen"] is False


@pytest.mark.unit
def test_rival_needs_effects_and_the_switch(monkeypatch):
    """No rival without effects in the model, without the trend among the candidates, or with ``GEOMETRIC_RIVAL``
    off: the choice is the plain one."""
    geometric, elastic = _models()
    q = np.random.default_rng(4).uniform(LO, HI, (80, 6))
    p = _measured(geometric, q, True, 5)
    assert _choose(geometric, geometric, q, p, candidates=("trend_gpr",)).without_effects is None
    assert _choose(elastic, geometric, q, p, candidates=("gpr",)).without_effects is None    # no trend offered
    monkeypatch.setattr(choice, "GEOMETRIC_RIVAL", False)
    ch = _choose(elastic, geometric, q, p, candidates=("trend_gpr",))
    assert ch.without_effects is None and not ch.on_geometry
