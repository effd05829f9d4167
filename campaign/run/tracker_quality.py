"""Measurement quality reported by the tracker itself, and where to aim it after a beam break.

* ``device_covariance(readings)``: the (3, 3) covariance (mm^2, tracker frame) a tracker reports per reading in
  ``TrackerReading.extra`` (std_x/y/z_mm and, if given, cov_xy/xz/yz_mm2), averaged over the point's readings;
  ``None`` when the readings carry no std devs (then the spec model of the config is used).
* ``check_device_stability(readings, stability_mm)``: a reading whose own total std dev exceeds the stability limit
  is unstable (``Unstable``), whatever the spread of the readings.
* ``SmrPredictor``: predicted SMR centre in the tracker frame for read-back joints (deg): the nominal model with
  the registration fitted to the points measured so far (>= 3, not collinear), else the rough tracker placement
  of the config (``tracker.position_in_base_mm``, axes assumed parallel).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from drivers.base import TrackerReading, Unstable
from robocal.kinematics.frames import fit_rigid
from robocal.kinematics.models import Kinematics, smr_base

STD_KEYS = ("std_x_mm", "std_y_mm", "std_z_mm")
COV_KEYS = ((0, 1, "cov_xy_mm2"), (0, 2, "cov_xz_mm2"), (1, 2, "cov_yz_mm2"))
MIN_REGISTRATION_POINTS = 3


def reading_covariance(reading: TrackerReading) -> np.ndarray | None:
    """(3, 3) mm^2 from one reading's extra (std devs on the diagonal, covariances off it), or None."""
    extra = reading.extra or {}
    if not all(k in extra for k in STD_KEYS):
        return None
    cov = np.diag([float(extra[k]) ** 2 for k in STD_KEYS])
    for i, j, key in COV_KEYS:
        if key in extra:
            cov[i, j] = cov[j, i] = float(extra[key])
    return cov


def device_covariance(readings: Sequence[TrackerReading]) -> np.ndarray | None:
    """Mean per-reading device covariance (3, 3) mm^2 over ``readings``; None unless every reading has one."""
    covs = [reading_covariance(r) for r in readings]
    if not covs or any(c is None for c in covs):
        return None
    return np.mean(covs, axis=0)


def check_device_stability(readings: Sequence[TrackerReading], stability_mm: float) -> None:
    """``Unstable`` if a reading's reported total std dev (sqrt(sx^2 + sy^2 + sz^2), mm) exceeds ``stability_mm``."""
    for r in readings:
        cov = reading_covariance(r)
        if cov is not None and np.sqrt(np.trace(cov)) > stability_mm:
            raise Unstable(f"tracker reports std dev {np.sqrt(np.trace(cov)):.4f} mm > stability limit "
                           f"{stability_mm:.4f} mm")


class SmrPredictor:
    """``predictor(q_deg (n,)) -> (3,)`` mm, tracker frame; ``observe(q_deg, p_tracker_mm)`` after each point."""

    def __init__(self, kin_nominal: Kinematics, tracker_position_in_base_mm: Sequence[float] | None = None) -> None:
        self.kin = kin_nominal
        T = np.eye(4)
        if tracker_position_in_base_mm is not None:
            T[:3, 3] = -np.asarray(tracker_position_in_base_mm, float)
        self.T_tracker_base_rough = T
        self._q_rad: list[np.ndarray] = []
        self._p_mm: list[np.ndarray] = []
        self._T: np.ndarray | None = None
        self._dirty = False
        self.source = "rough tracker position" if tracker_position_in_base_mm is not None else "none"

    def observe(self, q_deg: Sequence[float], p_tracker_mm: Sequence[float]) -> None:
        """Add one measured point (the registration is refitted when the next prediction is asked for)."""
        self._q_rad.append(np.radians(np.asarray(q_deg, float)))
        self._p_mm.append(np.asarray(p_tracker_mm, float))
        self._dirty = True

    def _refit(self) -> None:
        """Closed-form registration of all points so far (nominal SMR in the base frame -> measured)."""
        self._dirty = False
        if len(self._p_mm) < MIN_REGISTRATION_POINTS:
            return
        p_nom = smr_base(self.kin, np.array(self._q_rad))
        if np.linalg.matrix_rank(p_nom - p_nom.mean(0), tol=1.0) < 2:
            return
        self._T = fit_rigid(p_nom, np.array(self._p_mm))
        self.source = f"registration of {len(self._p_mm)} measured points"

    def __call__(self, q_deg: Sequence[float]) -> np.ndarray:
        if self._dirty:
            self._refit()
        T = self._T if self._T is not None else self.T_tracker_base_rough
        p_base = smr_base(self.kin, np.radians(np.asarray(q_deg, float))[None])[0]
        return T[:3, :3] @ p_base + T[:3, 3]
