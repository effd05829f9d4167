import json

import numpy as np

from robocal.effects.bases import joint_compliance
from robocal.identify.identification import calibrate
from robocal.kinematics.models import smr_tracker
from robocal.layers.calibrated_model import CalibratedModel, fit_idw_layer
from robocal.layers.idw import IDWResidual, idw, infer_lattice
from robocal.measure.stats import error_stats
from tests.cells import grid, irb2600, irb2600_poses, make_cell, measure

import pytest



def field(p):
    """A smooth 'robot error' field (mm) over base-frame positions (mm)."""
    return np.stack([0.2 * np.sin(p[:, 0] / 400), 0.1 * np.cos(p[:, 1] / 500), 1e-4 * p[:, 2]], axis=1)


@pytest.mark.unit
def test_idw_inside_a_cube_uses_its_eight_vertices():
    nodes = grid([0, 0, 0], [400, 400, 400], 200)
    rng = np.random.default_rng(0)
    nodes_actual = nodes + rng.normal(0, 0.5, nodes.shape)
    err = rng.normal(0, 0.1, nodes.shape)
    layer = IDWResidual.fit(nodes_actual, err)
    assert layer.grid_index is not None and layer.grid_index.shape == (3, 3, 3)
    p = np.array([[50.0, 120.0, -30.0]])
    # independent computation with eq. 14-15 over the cube [0,200]x[0,200]x[-200,0]
    lo = np.all((nodes >= [0, 0, -200]) & (nodes <= [200, 200, 0]), axis=1)
    d = np.linalg.norm(nodes_actual[lo] - p, axis=1)
    q = (1 / d**2) / np.sum(1 / d**2)
    np.testing.assert_allclose(layer.predict(None, p)[0], q @ err[lo], atol=1e-12)
    # exact hit returns the node's own error
    np.testing.assert_allclose(layer.predict(None, nodes_actual[4:5]), err[4:5], atol=1e-12)


@pytest.mark.unit
def test_outside_grid_and_missing_vertices_fall_back_to_nearest_neighbours():
    nodes = grid([0, 0, 0], [400, 400, 400], 200)
    err = np.arange(len(nodes) * 3, dtype=float).reshape(-1, 3)
    keep = np.ones(len(nodes), bool)
    keep[0] = False                              # a missing vertex
    layer = IDWResidual.fit(nodes[keep], err[keep], k_nearest=4)
    far = np.array([[1000.0, 30.0, -70.0], [-130.0, -160.0, -170.0]])
    pred = layer.predict(None, far)
    for i, p in enumerate(far):
        d = np.linalg.norm(nodes[keep] - p, axis=1)
        nn = np.argsort(d)[:4]
        np.testing.assert_allclose(pred[i], idw(d[nn][None], err[keep][nn][None], 2.0)[0], atol=1e-9)


@pytest.mark.unit
def test_random_nodes_have_no_lattice():
    assert infer_lattice(np.random.default_rng(0).uniform(0, 1000, (50, 3))) is None


@pytest.mark.unit
def test_correction_sign_target_minus_predicted_error():
    nodes = grid([1000, 0, 1000], [800, 800, 800], 100)
    layer = IDWResidual.fit(nodes + field(nodes), field(nodes))
    targets = np.random.default_rng(4).uniform([700, -300, 700], [1300, 300, 1300], (50, 3))
    command = targets - layer.predict(None, targets)        # the corrected command
    landed = command + field(command)                       # where the robot really goes
    wrong = targets + layer.predict(None, targets)
    before = np.linalg.norm(field(targets), axis=1)
    after = np.linalg.norm(landed - targets, axis=1)
    assert np.max(after) < 0.1 * np.max(before)
    assert np.mean(np.linalg.norm(wrong + field(wrong) - targets, axis=1)) > 1.5 * np.mean(before)


@pytest.mark.system
def test_idw_reduces_held_out_rms_under_joint_compliance():
    qc, qt = irb2600_poses()
    kin_rms, idw_rms = [], []
    for seed in range(2):
        rng = np.random.default_rng(seed)
        eff = joint_compliance(form="gravity")
        cell = make_cell(irb2600(), rng, effects=[(eff, 3 * np.array(eff.typical))])
        pc, cov = measure(cell, qc, rng)
        pt, _ = measure(cell, qt, rng)
        res = calibrate(irb2600(), qc, pc, cov)
        model = CalibratedModel(res.kinematics, fit_idw_layer(res.kinematics, qc, pc, weights=res.point_weights))
        kin_rms.append(error_stats(pt - smr_tracker(res.kinematics, qt)).rms_mm)
        idw_rms.append(error_stats(pt - model.smr_tracker(qt)).rms_mm)
    print(f"held-out RMS with joint compliance: kinematic {np.round(kin_rms, 4)} mm, + IDW {np.round(idw_rms, 4)} mm")
    assert all(i < 0.8 * k for i, k in zip(idw_rms, kin_rms))


@pytest.mark.system
def test_model_round_trips_through_json():
    qc, qt = irb2600_poses()
    rng = np.random.default_rng(5)
    cell = make_cell(irb2600(), rng)
    pc, cov = measure(cell, qc, rng)
    res = calibrate(irb2600(), qc, pc, cov)
    model = CalibratedModel(res.kinematics, fit_idw_layer(res.kinematics, qc, pc), {"robot": "irb2600"})
    back = CalibratedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    np.testing.assert_allclose(back.smr_tracker(qt), model.smr_tracker(qt), atol=1e-9)
    assert back.meta == {"robot": "irb2600"}
