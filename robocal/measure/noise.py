"""Laser-tracker uncertainty (the spherical error model: a range and a transverse term, each from the maximum
permissible error ``a + b * r`` of the tracker's ISO 10360-10 / ASME B89.4.19 specification, in the beam frame) and
the noise floor.

Standard uncertainties from MPE terms ``a + b * r`` read as expanded with coverage factor k:
``u_r = (a_r + b_r * r) / k`` along the beam, ``u_t = (a_t + b_t * r) / k`` transverse.
The tracker sits at the origin of the tracker frame. Lengths mm unless the name says um.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# ISO 9283 RP = mean + 3 std of the distance to the barycentre; for an isotropic 3-D Gaussian with
# per-axis sigma that distance is Maxwell distributed: mean 1.596 sigma, std 0.673 sigma.
RP_PER_SIGMA = 2.0 * np.sqrt(2.0 / np.pi) + 3.0 * np.sqrt(3.0 - 8.0 / np.pi)


@dataclass(frozen=True)
class TrackerUncertainty:
    """MPE terms of a tracker (defaults: Leica AT960 class, transverse 15 um + 6 um/m, ADM 10 um + 0.3 um/m).

    ``*_a_um`` micrometres (> 0), ``*_b_um_per_m`` micrometres per metre (>= 0), ``coverage_k`` > 0. Also the
    ``tracker.uncertainty`` section of a campaign config (which requires the four terms; ``coverage_k`` default 2).
    """
    transverse_a_um: float = 15.0
    transverse_b_um_per_m: float = 6.0
    range_a_um: float = 10.0
    range_b_um_per_m: float = 0.3
    coverage_k: float = 2.0

    def sigmas_mm(self, r_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_range, u_transverse) standard uncertainties in mm at distances r_mm."""
        r_m = np.asarray(r_mm, float) / 1000.0
        u_r = (self.range_a_um + self.range_b_um_per_m * r_m) / self.coverage_k / 1000.0
        u_t = (self.transverse_a_um + self.transverse_b_um_per_m * r_m) / self.coverage_k / 1000.0
        return u_r, u_t

    def covariance(self, p_tracker_mm: np.ndarray) -> np.ndarray:
        """Sigma_xyz (N, 3, 3) mm^2 = R diag(u_r^2, u_t^2, u_t^2) R^T with R = [e_r, e_phi, e_zeta]."""
        p = np.atleast_2d(np.asarray(p_tracker_mm, float))
        r = np.linalg.norm(p, axis=1)
        u_r, u_t = self.sigmas_mm(r)
        e_r = p / np.where(r > 0, r, 1.0)[:, None]     # at the origin (r = 0): isotropic u_t
        # Sigma = u_t^2 I + (u_r^2 - u_t^2) e_r e_r^T (the transverse plane is isotropic)
        return (u_t**2)[:, None, None] * np.eye(3) + ((u_r**2 - u_t**2)[:, None, None]) * e_r[:, :, None] * e_r[:, None, :]


def spherical_to_cartesian(r, az, zen):
    """x = r sin(zen) cos(az), y = r sin(zen) sin(az), z = r cos(zen); angles rad, r mm."""
    return np.stack([r * np.sin(zen) * np.cos(az), r * np.sin(zen) * np.sin(az), r * np.cos(zen)], axis=-1)


def cartesian_to_spherical(p):
    """Inverse of spherical_to_cartesian: (..., 3) -> (r, az, zen)."""
    p = np.asarray(p, float)
    r = np.linalg.norm(p, axis=-1)
    return r, np.arctan2(p[..., 1], p[..., 0]), np.arccos(np.clip(p[..., 2] / r, -1, 1))


def repeatability_sigma_mm(rp_mm: float) -> float:
    """Per-axis standard deviation of an isotropic robot repeatability given ISO 9283 RP (mm)."""
    return float(rp_mm) / RP_PER_SIGMA


def noise_floor_mm(p_tracker_mm: np.ndarray, tracker: TrackerUncertainty, repeatability_rp_mm: float = 0.0) -> float:
    """Expected RMS of the 3-D error of a perfect model over these points: sqrt(mean trace(Sigma_tracker
    + sigma_rep^2 I)). This is the physical limit the test-set RMS is judged against."""
    tr = np.trace(tracker.covariance(p_tracker_mm), axis1=1, axis2=2)
    s = repeatability_sigma_mm(repeatability_rp_mm)
    return float(np.sqrt(np.mean(tr + 3.0 * s**2)))


def noise_max_mm(floor_rms_mm: float, n: int) -> float:
    """The median of the largest of ``n`` 3-D errors of a perfect model (mm): isotropic Gaussian noise whose 3-D RMS
    is ``floor_rms_mm``, so |e|^2 / (floor^2 / 3) is chi-squared with 3 degrees of freedom and the largest of n is
    below m with probability F(m)^n = 1/2. A bound on the largest held-out error below it fails more often than not
    on noise alone."""
    from scipy.special import gammaincinv

    p = 0.5 ** (1.0 / max(int(n), 1))
    return float(floor_rms_mm / np.sqrt(3.0) * np.sqrt(2.0 * gammaincinv(1.5, p)))
