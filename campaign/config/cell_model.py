"""From a campaign config to the robocal objects it describes (nominal model, noise, options, simulated truth)."""
from __future__ import annotations

import numpy as np

from robocal.identify import CalibrationOptions
from robocal.kinematics import Kinematics
from robocal.noise import TrackerUncertainty, repeatability_sigma_mm

from .schema import CampaignConfig


def nominal_kinematics(cfg: CampaignConfig) -> Kinematics:
    """The controller's nominal model of the robot with the nominal SMR offset (base frame unregistered)."""
    j = cfg.robot.joints
    return Kinematics.from_table(cfg.robot.convention, [x.alpha_deg for x in j], [x.a_mm for x in j],
                                 [x.d_mm for x in j], [x.theta_deg for x in j], [x.q_min_deg for x in j],
                                 [x.q_max_deg for x in j], cfg.robot.hayati_joints,
                                 p_flange_smr_mm=cfg.tool.p_flange_smr_mm)


def tracker_uncertainty(cfg: CampaignConfig) -> TrackerUncertainty:
    """The tracker's MPE model as configured (the config holds robocal's class itself)."""
    return cfg.tracker.uncertainty


def measurement_covariance(cfg: CampaignConfig, p_tracker_mm: np.ndarray) -> np.ndarray:
    """(N, 3, 3) mm^2: tracker spherical model + robot repeatability (isotropic): the calibration weights."""
    s = repeatability_sigma_mm(cfg.robot.repeatability_mm)
    return tracker_uncertainty(cfg).covariance(p_tracker_mm) + s**2 * np.eye(3)


def device_measurement_covariance(cfg: CampaignConfig, device_cov_mm2: np.ndarray) -> np.ndarray:
    """(..., 3, 3) mm^2: the covariance the tracker reported + robot repeatability (isotropic), in place of the
    spec model when the device reports its own."""
    s = repeatability_sigma_mm(cfg.robot.repeatability_mm)
    return np.asarray(device_cov_mm2, float) + s**2 * np.eye(3)


def weights_covariance(cfg: CampaignConfig, ds) -> tuple[np.ndarray, str]:
    """(N, 3, 3) mm^2 calibration weights and their source: "device" when every row carries the covariance the
    tracker reported (``ds.cov_mm2``, already including the robot repeatability), else "spec" (the config's model)."""
    cov = getattr(ds, "cov_mm2", None)
    if cov is not None:
        return np.asarray(cov, float), "device"
    return measurement_covariance(cfg, ds.p_tracker_mm), "spec"


def calibration_options(cfg: CampaignConfig) -> CalibrationOptions:
    c = cfg.calibration
    return CalibrationOptions(method=c.method, weights=c.weights, k0=c.k0, k1=c.k1, ridge_mu=c.ridge_mu)
