"""Device statistics from tracker readings and the SMR prediction used to reacquire (campaign/run/tracker_quality.py)."""
import numpy as np
import pytest

from campaign.config.simulation import simulated_cell
from campaign.config.load import load_cell
from campaign.run.tracker_quality import SmrPredictor, check_device_stability, device_covariance
from drivers.base import TrackerReading, Unstable
from robocal.kinematics.models import smr_tracker
from tests.campaign.helpers import small_config


def _reading(sx, sy, sz, **cov):
    return TrackerReading((0.0, 0.0, 0.0), 0.0, {"std_x_mm": sx, "std_y_mm": sy, "std_z_mm": sz, **cov})


@pytest.mark.unit
def test_device_covariance_is_the_mean_of_the_readings():
    a = _reading(0.003, 0.004, 0.005, cov_xy_mm2=1e-6)
    b = _reading(0.005, 0.004, 0.003, cov_xy_mm2=3e-6)
    cov = device_covariance([a, b])
    assert cov[0, 0] == pytest.approx((0.003**2 + 0.005**2) / 2) and cov[1, 0] == cov[0, 1] == pytest.approx(2e-6)
    assert cov[0, 2] == 0.0
    assert device_covariance([a, TrackerReading((0.0, 0.0, 0.0), 0.0)]) is None      # all readings or none
    assert device_covariance([]) is None


@pytest.mark.unit
def test_device_std_beyond_the_stability_limit_is_unstable():
    check_device_stability([_reading(0.005, 0.005, 0.005)], 0.02)
    check_device_stability([TrackerReading((0.0, 0.0, 0.0), 0.0)], 0.02)              # no statistics: no check
    with pytest.raises(Unstable, match="std dev 0.0346"):
        check_device_stability([_reading(0.005, 0.005, 0.005), _reading(0.02, 0.02, 0.02)], 0.02)


@pytest.mark.unit
@pytest.mark.parametrize("name", ["irb2600", "ur10"])
def test_prediction_after_registration_is_within_a_few_mm(tmp_path, name):
    """Rotated tracker frame (the configs' simulated T_tracker_base), true geometry with errors: after 3 measured
    points the nominal model + registration predicts the SMR to a few mm (what FindReflector needs)."""
    cell = load_cell(small_config(tmp_path, name))
    cfg = cell.config
    truth = simulated_cell(cell).truth
    kin = cell.kinematics
    rng = np.random.default_rng(4)
    lo, hi = np.degrees(kin.q_min_rad), np.degrees(kin.q_max_rad)
    q_deg = rng.uniform(0.6 * lo, 0.6 * hi, size=(12, kin.n))
    p_true = smr_tracker(truth, np.radians(q_deg))
    predictor = SmrPredictor(kin, cfg.tracker.position_in_base_mm)
    for q, p in zip(q_deg[:3], p_true[:3]):
        predictor.observe(q, p)
    errors = [np.linalg.norm(predictor(q) - p) for q, p in zip(q_deg[3:], p_true[3:])]
    print(f"\n{name}: 3-point registration max error {max(errors):.2f} mm")
    assert max(errors) < 10.0, errors
    for q, p in zip(q_deg[3:8], p_true[3:8]):
        predictor.observe(q, p)
    errors = [np.linalg.norm(predictor(q) - p) for q, p in zip(q_deg[8:], p_true[8:])]
    assert max(errors) < 10.0 and predictor.source.startswith("registration of 8")


@pytest.mark.unit
def test_device_covariance_reaches_the_dataset_only_when_every_point_has_it():
    from campaign.data.log_dataset import dataset_from_log
    from campaign.run.log_reader import LogContents

    def record(i, source):
        cov = (np.eye(3) * (1e-4 if source == "device" else 4e-4)).tolist()
        return {"point_id": f"P{i}", "set": "calib", "q_read_deg": [0.0] * 6, "p_tracker_mm": [float(i), 0.0, 0.0],
                "cov_mm2": cov, "cov_source": source, "t_end_s": float(i)}
    device = dataset_from_log(LogContents(start={}, points=[record(i, "device") for i in range(4)], path="log"))
    assert device.cov_mm2.shape == (4, 3, 3) and device.cov_mm2[0, 0, 0] == 1e-4
    mixed = dataset_from_log(LogContents(start={}, points=[record(0, "spec")] +
                                             [record(i, "device") for i in range(1, 4)], path="log"))
    assert mixed.cov_mm2 is None                        # a resumed run with another tracker: the spec model for all
