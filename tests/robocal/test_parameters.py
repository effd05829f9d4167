"""The parameter record of a calibrated model (robocal.identify.parameters): its JSON form, and the std of the geometry
that the joint fit of geometry + effects reports (checked against a finite-difference covariance)."""
import json

import numpy as np
import pytest

from robocal.diagnose.selfcheck import truth_input
from robocal.effects.model import EffectChoice, elastic_smr_tracker
from robocal.effects.fit import calibrate_elastic
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.identify.whitened import whiten, whitening
from robocal.kinematics.models import ParamLayout, apply_update
from robocal.layers.calibrated_model import CalibratedModel
from robocal.identify.parameters import GEOMETRY, GEOMETRY_AND_EFFECTS, ParameterTable
from robocal.simulation.truth_cell import TruthProtocol, simulate


def _geometric(seed: int = 5):
    camp = simulate([], seed, TruthProtocol(n_calib=150, n_test=10, check_poses=3, check_repeats=3))
    inp = truth_input(camp)
    cal = np.flatnonzero(inp.calib)
    q, p, cov = inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal]
    meta = {k: (None if v is None else np.asarray(v)[cal]) for k, v in inp.meta().items()}
    return q, p, cov, meta, calibrate(inp.kin, q, p, cov, CalibrationOptions(method="lm"))


@pytest.mark.system
def test_the_table_round_trips_through_model_json_with_angles_in_degrees():
    *_, geo = _geometric()
    table = geo.table()
    assert table.fit == GEOMETRY and [r.name for r in table.rows] == list(ParamLayout.of(geo.kinematics).names)
    doc = json.loads(json.dumps(CalibratedModel(geo.kinematics, parameters=table).to_dict()))
    rows = {r["name"]: r for r in doc["parameters"]["rows"]}
    assert rows["theta2"]["unit"] == "deg" and rows["theta2"]["value"] == pytest.approx(np.degrees(geo.kinematics.theta_rad[1]))
    assert rows["a2"]["value"] == geo.kinematics.a_mm[1] and rows["base_tx"]["value"] is None
    i = list(geo.names).index("alpha3")
    assert rows["alpha3"]["std"] == pytest.approx(np.degrees(geo.std[i]), rel=1e-15)
    assert rows["alpha3"]["delta"] == pytest.approx(np.degrees(geo.delta[i]), rel=1e-15)
    back = CalibratedModel.from_dict(doc).parameters
    assert back == ParameterTable.from_dict(doc["parameters"])
    for a, b in zip(back.rows, table.rows):
        assert (a.name, a.unit, a.identified) == (b.name, b.unit, b.identified)
        assert a.delta == pytest.approx(b.delta, rel=1e-14, abs=1e-300) and (a.std is None) == (b.std is None)
    del doc["parameters"]                                       # a model.json of an earlier version
    assert CalibratedModel.from_dict(doc).parameters is None


@pytest.mark.system
def test_the_joint_fit_reports_the_geometry_std_of_its_own_covariance():
    """geometry_std = sqrt(diag(sigma0^2 (J^T J)^-1)) of the whitened Jacobian over the identified geometry and the
    effect's parameters, J here by central differences of the elasto-geometric prediction at the solution."""
    q, p, cov, meta, geo = _geometric()
    layout = ParamLayout.of(geo.kinematics)
    cols = np.array([layout.index(n) for n in geo.identified])
    choice = EffectChoice("gear_cyclic", (("joint", 1), ("harmonics", (1,))))
    el = calibrate_elastic(geo.kinematics, cols, q, p, cov, meta, [choice], CalibrationOptions(method="lm"))
    built, x0 = choice.build(el.kinematics.n), el.effects[0].values
    W = whitening(cov, len(q))

    def predict(v):
        full = np.zeros(layout.size)
        full[cols] = v[:len(cols)]
        return whiten(W, elastic_smr_tracker(apply_update(el.kinematics, full), q, meta, [(built, x0 + v[len(cols):])]))
    P, h = len(cols) + len(x0), 1e-6
    J = np.stack([(predict(np.eye(P)[k] * h) - predict(-np.eye(P)[k] * h)) / (2 * h) for k in range(P)], axis=-1)
    J = J.reshape(-1, P)
    std = el.sigma0 * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    np.testing.assert_allclose(el.geometry_std[cols], std[:len(cols)], rtol=1e-4)
    assert np.all(np.isnan(np.delete(el.geometry_std, cols)))
    table = el.table(geo.start, geo.identified)
    assert table.fit == GEOMETRY_AND_EFFECTS and table.sigma0 == el.sigma0
    assert [r.name for r in table.rows if r.identified] == list(geo.identified)
    assert table.row("a2").value == el.kinematics.a_mm[1] and table.row("a2").delta == pytest.approx(
        el.kinematics.a_mm[1] - geo.start.a_mm[1], abs=1e-12)
