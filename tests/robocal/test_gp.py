"""GPR error model (seed 003 §1.2): likelihood gradient, recovery, residual layer, campaign reprocess with gpr."""
import dataclasses
import json

import numpy as np
import pytest
import yaml

from campaign.cli import main
from campaign.data.interchange_csv import read_csv, write_csv
from campaign.calibrate.outputs import load_model
from robocal.effects.bases import joint_compliance
from robocal.layers.gp import GaussianProcess, MultiOutputGP, neg_log_marginal_likelihood, se_ard
from robocal.layers.gp_layer import GPRResidual, fit_gpr_layer, gp_inputs
from robocal.identify.identification import calibrate
from robocal.kinematics.models import fk, smr_tracker
from robocal.layers.calibrated_model import CalibratedModel
from robocal.simulation.payload import DeflectionModel, HeavyPayloadCell, deflected_flange, irb4600, random_configurations
from robocal.layers.rbf import RBFNetwork
from robocal.measure.stats import error_stats
from tests.campaign.helpers import read_report, small_config
from tests.cells import irb2600, irb2600_poses, make_cell, measure



def smooth(X):
    """A smooth 'robot error' (mm) of 6 joint angles (rad) that ignores joint 6."""
    return 0.3 * np.sin(1.5 * X[:, 1] + X[:, 2]) + 0.1 * np.cos(X[:, 0]) * X[:, 3] + 0.05 * X[:, 4] ** 2


@pytest.mark.unit
def test_likelihood_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-1, 1, (40, 3)), rng.uniform(0, 50, 40)])   # joints rad + payload kg
    y = np.sin(2 * X[:, 0]) + 0.01 * X[:, 3] + rng.normal(0, 0.02, 40)
    Xc, yc = X - X.mean(0), y - y.mean()
    for log_theta in (np.log([0.7, 0.05, 0.8, 1.5, 30.0, 20.0]), np.log([2.0, 0.3, 0.2, 5.0, 1.0, 200.0])):
        L, g = neg_log_marginal_likelihood(log_theta, Xc, yc)
        h = 1e-6
        fd = np.array([(neg_log_marginal_likelihood(log_theta + h * e, Xc, yc, grad=False)
                        - neg_log_marginal_likelihood(log_theta - h * e, Xc, yc, grad=False)) / (2 * h)
                       for e in np.eye(len(log_theta))])
        np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * np.abs(g).max())
        # eq. 9 directly
        H = se_ard(Xc, Xc, np.exp(log_theta[2:]), np.exp(log_theta[0])) + np.exp(2 * log_theta[1]) * np.eye(40)
        direct = 0.5 * yc @ np.linalg.solve(H, yc) + 0.5 * np.linalg.slogdet(H)[1] + 20 * np.log(2 * np.pi)
        assert L == pytest.approx(direct, rel=1e-10)


@pytest.mark.unit
def test_gp_recovers_a_smooth_function_with_calibrated_uncertainty():
    rng = np.random.default_rng(1)
    lo, hi = np.radians([-40, -20, -50, -60, -90, -90]), np.radians([40, 50, 20, 60, -20, 90])
    X, Xt = rng.uniform(lo, hi, (150, 6)), rng.uniform(lo, hi, (300, 6))
    noise = 0.01
    gp = GaussianProcess.fit(X, smooth(X) + rng.normal(0, noise, 150), n_restarts=2, seed=0)
    mean, var = gp.predict(Xt, return_var=True)
    err = smooth(Xt) - mean
    print(f"GP on 150 points: test RMS {np.sqrt(np.mean(err**2)):.4f} mm (signal std {smooth(Xt).std():.3f}), "
          f"sigma_n {gp.sigma_n:.4f}, lengths {np.round(gp.length, 2)}")
    assert np.sqrt(np.mean(err**2)) < 0.02
    assert gp.sigma_n == pytest.approx(noise, rel=0.3)
    assert gp.length[5] > 10 * gp.length[1]                    # ARD: joint 6 is irrelevant
    z = (smooth(Xt) + rng.normal(0, noise, 300) - mean) / np.sqrt(var)
    assert 0.85 < np.mean(np.abs(z) < 2) <= 1.0                 # eq. 8 includes sigma_n^2: new measurements
    _, var_latent = gp.predict(Xt, return_var=True, include_noise=False)
    np.testing.assert_allclose(var - var_latent, gp.sigma_n**2, rtol=1e-9)
    far = gp.predict(X[:1] + 10.0, return_var=True)[1]          # far from the data: the prior
    assert far[0] == pytest.approx(gp.sigma_f**2 + gp.sigma_n**2, rel=1e-6)


@pytest.mark.unit
def test_rbf_network_fits_the_same_function_less_well():
    rng = np.random.default_rng(2)
    X, Xt = rng.uniform(-1, 1, (100, 6)), rng.uniform(-1, 1, (200, 6))
    y = smooth(X) + rng.normal(0, 0.01, 100)
    rbf = RBFNetwork.fit(X, y, seed=0)
    gp = MultiOutputGP.fit(X, y[:, None], n_restarts=1)
    e_rbf = np.sqrt(np.mean((rbf.predict(Xt)[:, 0] - smooth(Xt)) ** 2))
    e_gp = np.sqrt(np.mean((gp.predict(Xt)[:, 0] - smooth(Xt)) ** 2))
    print(f"100 points: RBF network RMS {e_rbf:.4f}, GPR RMS {e_gp:.4f} (signal std {smooth(Xt).std():.3f})")
    assert e_rbf < 0.5 * smooth(Xt).std() and e_gp < e_rbf


@pytest.mark.system
def test_gpr_layer_reduces_held_out_rms_and_round_trips_through_json():
    qc, qt = irb2600_poses()
    rng = np.random.default_rng(3)
    eff = joint_compliance(form="gravity")
    cell = make_cell(irb2600(), rng, effects=[(eff, 3 * np.array(eff.typical))])
    pc, cov = measure(cell, qc, rng)
    pt, _ = measure(cell, qt, rng)
    res = calibrate(irb2600(), qc, pc, cov)
    layer = fit_gpr_layer(res.kinematics, qc, pc, res.point_weights, n_restarts=0)
    model = CalibratedModel(res.kinematics, layer, {"robot": "irb2600"})
    kin_rms = error_stats(pt - smr_tracker(res.kinematics, qt)).rms_mm
    gpr_rms = error_stats(pt - model.smr_tracker(qt)).rms_mm
    std = np.linalg.norm(layer.predict_std(qt), axis=1)
    print(f"held-out RMS with joint compliance: kinematic {kin_rms:.4f} mm, + GPR {gpr_rms:.4f} mm, "
          f"mean predictive std {std.mean():.4f} mm")
    assert gpr_rms < 0.8 * kin_rms
    assert 0.5 * gpr_rms < np.sqrt(np.mean(std**2)) < 2 * gpr_rms
    back = CalibratedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    assert isinstance(back.residual, GPRResidual) and back.residual.kind == "gpr"
    np.testing.assert_allclose(back.smr_tracker(qt), model.smr_tracker(qt), atol=1e-9)
    np.testing.assert_allclose(back.residual.predict_std(qt), layer.predict_std(qt), atol=1e-12)


@pytest.mark.system
def test_payload_as_an_input_and_the_deflection_grows_with_payload():
    kin = irb4600()
    q = random_configurations(40, seed=0)
    p0 = fk(kin, q)[:, :3, 3]
    defl = [np.linalg.norm(deflected_flange(kin, q, m)[:, :3, 3] - p0, axis=1).mean() for m in (0, 5, 20, 46)]
    assert np.all(np.diff(defl) > 0) and 0.3 < defl[-1] < 5.0
    rigid = DeflectionModel(compliance_rad_per_Nm=(0,) * 6, EI_upper_Nmm2=1e30, EI_fore_Nmm2=1e30)
    np.testing.assert_allclose(deflected_flange(kin, q, 46.0, rigid), fk(kin, q), atol=1e-9)

    cell = HeavyPayloadCell(kin, repeatability_rp_mm=0.0)
    qa = random_configurations(80, seed=1)
    X, Y = [], []
    for m in (5.0, 20.0, 45.0):
        p, _ = cell.measure(qa, m, kin.p_flange_smr_mm[None], np.random.default_rng(int(m)))
        X.append(gp_inputs(qa, m))
        Y.append(p[:, 0] - smr_tracker(kin, qa))
    layer = GPRResidual(MultiOutputGP.fit(np.concatenate(X), np.concatenate(Y), n_restarts=0), uses_payload=True)
    with pytest.raises(ValueError, match="payload"):
        layer.predict(qa[:3])
    qt = random_configurations(30, seed=2)
    truth = cell.true_points(qt, 30.0, kin.p_flange_smr_mm[None])[:, 0] - smr_tracker(kin, qt)
    err = np.linalg.norm(layer.with_payload(30.0).predict(qt) - truth, axis=1)
    print(f"payload 30 kg never trained (5, 20, 45 kg): mean error {err.mean():.4f} mm, deflection "
          f"{np.linalg.norm(truth, axis=1).mean():.3f} mm")
    assert err.mean() < 0.1 * np.linalg.norm(truth, axis=1).mean()
    back = GPRResidual.from_dict(json.loads(json.dumps(layer.with_payload(30.0).to_dict())))
    np.testing.assert_allclose(back.predict(qt), layer.predict(qt, None, 30.0), atol=1e-9)


@pytest.mark.system
def test_campaign_reprocess_with_gpr_residual(tmp_path, capsys):
    """`campaign run` then `campaign reprocess` with calibration.residual: gpr on a simulated dataset; the layer's
    calibration RMS is shown next to its CV-predicted held-out RMS, labelled, in the terminal, report and HTML."""
    cfg = small_config(tmp_path, "irb4600", **{"calibration.residual": "gpr", "tool.payload_kg": 40.0,
                                                "simulation.effects": [{"name": "joint_compliance", "scale": 3.0}]})
    assert yaml.safe_load(cfg.read_text())["calibration"]["residual"] == "gpr"
    run = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    out = tmp_path / "re"
    assert main(["reprocess", str(run / "data.csv"), "--config", str(cfg), "--out", str(out)]) == 0
    live, again = read_report(run), read_report(out)
    comp = again.final
    lay = comp.layer
    assert lay.kind == "gpr" and lay.approximation == "exact" and 0 < lay.n_train <= again.n.calib
    assert lay.calib_rms_mm == comp.calib.rms_mm and lay.test_rms_mm == comp.test.rms_mm
    assert lay.cv_predicted_rms_mm == again.residual_choice.candidates["gpr"]["cv_rms_mm"]
    assert lay.noise_floor_mm == again.noise_floor_mm and lay.noise_mm >= lay.noise_floor_mm * (1 - 1e-9)
    shown = capsys.readouterr().out
    assert f"calibration RMS {lay.calib_rms_mm:.3f} mm is a fit to its own points, not an accuracy; " \
           f"CV-predicted held-out RMS {lay.cv_predicted_rms_mm:.3f} mm" in shown
    html = (out / "report.html").read_text()
    assert 'id="layer-honesty"' in html and "not an accuracy" in html
    assert f'data-key="stages.compensated.layer.cv_predicted_rms_mm" data-scale="1.0" data-fmt=".4f" ' \
           f'data-value="{lay.cv_predicted_rms_mm!r}"' in html
    assert again.method.residual == "gpr"
    assert comp.test.rms_mm == pytest.approx(live.final.test.rms_mm, rel=1e-9)
    std = comp.test_pred_std_mm
    assert std.n == comp.test.n == len(std.per_point_mm) > 0
    kinematic = again.stages["kinematic"].test.rms_mm
    print(f"gpr reprocess: kinematic RMS {kinematic:.4f} mm, compensated "
          f"{comp.test.rms_mm:.4f} mm, predictive std mean {std.mean_mm:.4f} mm")
    assert comp.test.rms_mm < kinematic
    assert 0.3 * comp.test.rms_mm < std.rms_mm < 3 * comp.test.rms_mm
    model = json.loads((out / "model.json").read_text())
    assert model["residual"]["kind"] == "gpr"
    assert main(["reprocess", str(run), "--config", str(cfg), "--out", str(tmp_path / "from-log")]) == 0
    # a CSV whose payload varies over the calib rows: the payload becomes a GPR input, bound to tool.payload_kg
    ds = read_csv(run / "data.csv")
    write_csv(tmp_path / "pay.csv", dataclasses.replace(ds, payload_kg=np.where(np.arange(len(ds)) % 2, 40.0, 20.0)))
    assert main(["reprocess", str(tmp_path / "pay.csv"), "--config", str(cfg), "--out", str(tmp_path / "pay")]) == 0
    layer = load_model(tmp_path / "pay" / "model.json").residual
    assert layer.uses_payload and layer.payload_kg == 40.0
    assert read_report(tmp_path / "pay").final.test_pred_std_mm.n > 0
