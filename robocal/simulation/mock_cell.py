"""A simulated cell: the "real" robot behind the mock drivers and the recovery tests.

Truth = nominal model + random geometric errors of seed 000 Table 2 magnitude + chosen effects;
measurements add robot repeatability and laser-tracker noise with the spherical model.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from robocal.effects.bases import apply_effects
from robocal.kinematics.models import Kinematics
from robocal.measure.noise import TrackerUncertainty, noise_floor_mm, repeatability_sigma_mm

# seed 000 Table 2: identified D-H errors of an IRB 2600 (alpha deg, a mm, d mm, theta deg), joints 1..6
SEED000_TABLE2 = np.array([
    [-0.0075, -0.2411, -0.3452, 0.0817],
    [-0.0035, 0.3212, -0.0181, -0.0350],
    [-0.0028, 0.4681, 0.0000, -0.0164],
    [0.3780, 0.1615, 0.1751, 0.0100],
    [-0.0113, 0.0524, 0.0081, 0.0980],
    [-0.0063, 0.0301, -0.0482, 0.0011],
])


def random_geometric_errors(nominal: Kinematics, rng: np.random.Generator, scale: float = 1.0,
                            beta_deg: float = 0.01) -> Kinematics:
    """Truth geometry: every DH parameter off by |Table 2 value| x U(0.5, 1.5) x random sign (rows cycled
    for n != 6; a floor of 0.05 mm / 0.005 deg so no parameter is exactly right), Hayati joints get a
    beta error of about ``beta_deg``."""
    n = nominal.n
    mag = np.abs(SEED000_TABLE2[np.arange(n) % 6])
    mag = np.maximum(mag, [0.005, 0.05, 0.05, 0.005])
    err = scale * mag * rng.uniform(0.5, 1.5, (n, 4)) * rng.choice([-1.0, 1.0], (n, 4))
    err[:nominal.n_track] = 0.0                               # a track's DH row is unused
    beta = np.where(nominal.hayati, scale * np.radians(beta_deg) * rng.uniform(-1.5, 1.5, n), 0.0)
    truth = nominal.with_(alpha_rad=nominal.alpha_rad + np.radians(err[:, 0]), a_mm=nominal.a_mm + err[:, 1],
                          d_mm=nominal.d_mm + err[:, 2], theta_rad=nominal.theta_rad + np.radians(err[:, 3]),
                          beta_rad=nominal.beta_rad + beta)
    if nominal.track is None:
        return truth
    # a track: its direction off by ~0.1 mrad (0.6 mm over 6 m), its scale by ~50 ppm (rack and pinion, encoder)
    return truth.with_(track=nominal.track * (1 + scale * 5e-5 * rng.uniform(-1.5, 1.5))
                       + scale * 1e-4 * rng.uniform(-1.5, 1.5, 3))


@dataclass(frozen=True, eq=False)
class SimulatedCell:
    """Robot truth + measurement noise.

    ``truth`` carries the true geometry, T_tracker_base and SMR offset; ``effects`` is a tuple of
    (Effect, params) pairs; ``repeatability_rp_mm`` is the ISO 9283 RP of the robot.
    """
    truth: Kinematics
    effects: tuple = ()
    tracker: TrackerUncertainty = TrackerUncertainty()
    repeatability_rp_mm: float = 0.0

    def true_smr_tracker(self, q_rad: np.ndarray, meta: Mapping | None = None) -> np.ndarray:
        """Noise-free SMR positions (N, 3) mm in the tracker frame."""
        return apply_effects(self.truth, q_rad, meta or {}, self.effects)

    def measure(self, q_rad: np.ndarray, rng: np.random.Generator, meta: Mapping | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Measured SMR positions (N, 3) mm and their tracker covariance (N, 3, 3) mm^2."""
        p = self.true_smr_tracker(q_rad, meta)
        s_rep = repeatability_sigma_mm(self.repeatability_rp_mm)
        p = p + rng.normal(0.0, s_rep, p.shape) if s_rep > 0 else p
        cov = self.tracker.covariance(p)
        noise = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal(p.shape))
        return p + noise, cov

    def noise_floor(self, q_rad: np.ndarray, meta: Mapping | None = None) -> float:
        """Expected 3-D RMS of the measurement noise at these poses (mm)."""
        return noise_floor_mm(self.true_smr_tracker(q_rad, meta), self.tracker, self.repeatability_rp_mm)


def readback_joints_deg(q_cmd_deg: np.ndarray, move_deg: np.ndarray, lag_deg_per_deg: np.ndarray,
                        noise_deg: float, rng: np.random.Generator) -> np.ndarray:
    """Read-back joints (N, n) deg of a robot standing at q_cmd_deg (N, n) whose controller reports a lag
    proportional to the signed last move ``move_deg`` (N, n): q_cmd + lag_j * move_j + N(0, noise_deg)
    (real arms: about -0.0005 deg per deg of move on J1-J3)."""
    q = np.asarray(q_cmd_deg, float) + np.asarray(lag_deg_per_deg, float) * np.asarray(move_deg, float)
    return q + rng.normal(0.0, noise_deg, q.shape) if noise_deg > 0 else q


def tracker_drift_mm(p_tracker_mm: np.ndarray, t_s: np.ndarray, v_mm_per_h, w_rad_per_h,
                     tau_s: float = 0.0) -> np.ndarray:
    """Apparent displacement (N, 3) mm of points read at p_tracker_mm (N, 3) at times t_s (N,) s when the
    tracker's registration drifts: u(t) (v + w x p), u = t in hours, or with tau_s > 0 the settling curve
    tau_h (1 - exp(-t / tau)) with the same initial rate (v mm/h, w rad/h, tracker frame)."""
    t = np.asarray(t_s, float)
    u = t / 3600.0 if tau_s <= 0 else tau_s / 3600.0 * (1.0 - np.exp(-t / tau_s))
    p = np.atleast_2d(np.asarray(p_tracker_mm, float))
    return np.atleast_1d(u)[:, None] * (np.asarray(v_mm_per_h, float) + np.cross(np.asarray(w_rad_per_h, float), p))
