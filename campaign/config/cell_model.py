"""The numerics a campaign config describes, built once per command: :class:`CellModel` (nominal model, tracker
noise model, robot repeatability, payload and gravity model, calibration options). The CLI and the workflows build
it (``campaign.config.load.load_cell``) and pass it down; no module below them rebuilds any of it from the config.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.kinematics.gravity import GravityModel
from robocal.identify.identification import CalibrationOptions
from robocal.kinematics.models import Kinematics
from robocal.measure.noise import TrackerUncertainty, noise_floor_mm, repeatability_sigma_mm

from .schema import CampaignConfig


def nominal_kinematics(cfg: CampaignConfig) -> Kinematics:
    """The controller's nominal model of the robot with the nominal SMR offset (base frame unregistered)."""
    j = cfg.robot.joints
    return Kinematics.from_table(cfg.robot.convention, [x.alpha_deg for x in j], [x.a_mm for x in j],
                                 [x.d_mm for x in j], [x.theta_deg for x in j], [x.q_min_deg for x in j],
                                 [x.q_max_deg for x in j], cfg.robot.hayati_joints,
                                 p_flange_smr_mm=cfg.tool.p_flange_smr_mm,
                                 track_axis=None if cfg.robot.track is None else cfg.robot.track.axis)


@dataclass(frozen=True, eq=False)
class CellModel:
    """The cell of a config as robocal objects. ``config`` is the config it was built from: settings (plan, motion
    caps, correction, output) are read there; the numerics only here.

    ``kinematics``: the controller's nominal model with the nominal SMR 1 offset (base frame unregistered);
    ``tracker``: the tracker's MPE model (mm); ``repeatability_mm``: the robot's ISO 9283 repeatability spec;
    ``payload_kg`` (0.0 without a payload) and ``gravity`` (link masses, payload centre of gravity, direction of
    gravity: the one gravity-torque model of the physical effects); ``options``: robocal's calibration options of
    the ``calibration`` section."""
    config: CampaignConfig
    kinematics: Kinematics
    tracker: TrackerUncertainty
    repeatability_mm: float
    payload_kg: float
    gravity: GravityModel
    options: CalibrationOptions

    @classmethod
    def from_config(cls, cfg: CampaignConfig) -> "CellModel":
        """The model of a loaded config (every key already checked: this raises nothing)."""
        r, c = cfg.robot, cfg.calibration
        gravity = GravityModel.of_robot(r.n_joints, r.link_masses_kg, r.mass_kg, cfg.tool.payload_cog_flange_mm,
                                        r.gravity_direction_base)
        return cls(cfg, nominal_kinematics(cfg), cfg.tracker.uncertainty, r.repeatability_mm,
                   float(cfg.tool.payload_kg or 0.0), gravity,
                   CalibrationOptions(method=c.method, weights=c.weights, k0=c.k0, k1=c.k1, ridge_mu=c.ridge_mu))

    @property
    def name(self) -> str:
        return self.config.name

    def covariance(self, p_tracker_mm: np.ndarray) -> np.ndarray:
        """(N, 3, 3) mm^2 at SMR positions (N, 3) mm, tracker frame: the tracker's spherical model + the robot's
        repeatability (isotropic): the calibration weights."""
        s = repeatability_sigma_mm(self.repeatability_mm)
        return self.tracker.covariance(p_tracker_mm) + s**2 * np.eye(3)

    def device_covariance(self, device_cov_mm2: np.ndarray) -> np.ndarray:
        """(..., 3, 3) mm^2: the covariance the tracker reported + the robot's repeatability (isotropic), in place
        of the spec model when the device reports its own."""
        s = repeatability_sigma_mm(self.repeatability_mm)
        return np.asarray(device_cov_mm2, float) + s**2 * np.eye(3)

    def weights(self, ds) -> tuple[np.ndarray, str]:
        """(N, 3, 3) mm^2 calibration weights of a dataset and their source: "device" when every row carries the
        covariance the tracker reported (``ds.cov_mm2``, already including the robot repeatability), else "spec"
        (:meth:`covariance`)."""
        cov = getattr(ds, "cov_mm2", None)
        if cov is not None:
            return np.asarray(cov, float), "device"
        return self.covariance(ds.p_tracker_mm), "spec"

    def noise_floor_mm(self, p_tracker_mm: np.ndarray) -> float:
        """The specs' noise floor (mm RMS) at SMR positions (N, 3) mm: tracker model + robot repeatability."""
        return noise_floor_mm(p_tracker_mm, self.tracker, self.repeatability_mm)
