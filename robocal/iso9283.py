"""ISO 9283 pose and distance characteristics (position part), and the standard's test cube.

Pure numerics, mm throughout. For one pose j measured in n cycles (attained positions ``p_mm`` (n, 3), the
commanded position ``p_cmd_mm`` (3,)):

* AP (pose accuracy): the barycentre ``p_bar = mean(p_i)``; ``APx, APy, APz = p_bar - p_cmd``;
  ``AP = |p_bar - p_cmd|``.
* RP (pose repeatability): ``l_i = |p_i - p_bar|``, ``l_bar = mean(l_i)``,
  ``S_l = sqrt(sum((l_i - l_bar)^2) / (n - 1))``, ``RP = l_bar + 3 S_l``.

For two poses measured in the same n cycles (``D_i = |p1_i - p2_i|``, commanded ``D_c = |c1 - c2|``):

* AD (distance accuracy) ``= mean(D_i) - D_c``, per axis ``ADx = mean(x1_i - x2_i) - (c1x - c2x)`` etc.
* RD (distance repeatability) ``= 3 S_D`` with ``S_D = sqrt(sum((D_i - mean D)^2) / (n - 1))`` (stated as +-RD).

The measured RP includes the instrument's scatter. :func:`split_rp` separates the two in quadrature: the
tracker's RP is the RP an isotropic scatter with the tracker's mean squared spread ``trace(Sigma_tracker)`` gives
(``RP_PER_SIGMA * sqrt(trace / 3)``); the robot's ``RP_robot = sqrt(RP^2 - RP_tracker^2)`` (0 when the tracker's
share is the larger). The mean squared spreads add exactly; the RP of each is that of the isotropic scatter of
the same spread (exact for isotropic Gaussian scatter, where RP is proportional to sigma; an AT960-class tracker,
much better in range than across the beam, alone shows about 6 % more than its isotropic equivalent). Its
interval maps ``RP -+ k u(RP)`` through the same quadrature, ``u(RP)`` being the jackknife standard uncertainty of
the measured RP over the n cycles.

The cube: the largest cube inside a box (edges parallel to the base axes); P1 is its centre and P2..P5 lie on
the diagonals of the diagonal plane through two opposite edges, at 0.1 L from the corners (L = diagonal length),
i.e. ``centre + 0.8 * (corner - centre)``. P2/P4 and P3/P5 are the ends of one diagonal each.
The cycle visits P1, P5, P4, P3, P2 so each pose is always approached from the same neighbour.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from robocal.measure.noise import RP_PER_SIGMA

__all__ = ["COVERAGE_K", "CYCLE_ORDER", "DEFAULT_CYCLES", "POSE_NAMES", "DistanceCharacteristics", "PoseCharacteristics",
           "RepeatabilitySplit", "characteristics", "cube_poses", "distance_characteristics", "largest_cube",
           "pose_characteristics", "split_rp"]
POSE_NAMES = ("P1", "P2", "P3", "P4", "P5")
CYCLE_ORDER = (0, 4, 3, 2, 1)          # P1 -> P5 -> P4 -> P3 -> P2 (-> P1 of the next cycle)
CORNER_FRACTION = 0.1                  # P2..P5 at 0.1 L from the corners along the plane's diagonals
DEFAULT_CYCLES = 30
COVERAGE_K = 2.0                       # the robot RP's interval: RP -+ 2 u(RP), about 95 %


@dataclass(frozen=True)
class PoseCharacteristics:
    """AP and RP of one pose (mm). ``l_mean_mm``/``s_l_mm``: mean and standard deviation of l_i."""
    pose: str
    n: int
    ap_mm: float
    apx_mm: float
    apy_mm: float
    apz_mm: float
    rp_mm: float
    l_mean_mm: float
    s_l_mm: float

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class DistanceCharacteristics:
    """AD (signed, mm; per axis too) and RD (mm, stated as +-RD) between two poses."""
    poses: tuple[str, str]
    n: int
    distance_cmd_mm: float
    distance_mean_mm: float
    ad_mm: float
    adx_mm: float
    ady_mm: float
    adz_mm: float
    rd_mm: float

    def to_dict(self) -> dict:
        d = asdict(self)
        d["poses"] = list(self.poses)
        return d


@dataclass(frozen=True)
class RepeatabilitySplit:
    """The measured RP of one pose (mm) with its jackknife standard uncertainty ``u_rp_mm``, the tracker's share
    ``rp_tracker_mm`` and the robot's ``rp_robot_mm`` (tracker removed in quadrature), with the robot's interval
    ``[rp_robot_low_mm, rp_robot_high_mm]`` at coverage factor ``k``."""
    rp_mm: float
    u_rp_mm: float
    rp_tracker_mm: float
    rp_robot_mm: float
    rp_robot_low_mm: float
    rp_robot_high_mm: float
    k: float

    def to_dict(self) -> dict:
        return asdict(self)


def _l_stats(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """l-bar and S_l of attained positions (..., n, 3) mm around their barycentre: arrays (...)."""
    l = np.linalg.norm(p - p.mean(axis=-2, keepdims=True), axis=-1)
    return l.mean(axis=-1), np.std(l, axis=-1, ddof=1)


def pose_characteristics(p_mm: np.ndarray, p_cmd_mm: np.ndarray, pose: str = "") -> PoseCharacteristics:
    """AP, APx/y/z and RP of attained positions ``p_mm`` (n, 3) against the commanded ``p_cmd_mm`` (3,)."""
    p = _positions(p_mm)
    ap = p.mean(axis=0) - np.asarray(p_cmd_mm, float)
    l_mean, s_l = (float(v) for v in _l_stats(p))
    return PoseCharacteristics(pose, len(p), float(np.linalg.norm(ap)), float(ap[0]), float(ap[1]), float(ap[2]),
                               l_mean + 3.0 * s_l, l_mean, s_l)


def _positions(p_mm) -> np.ndarray:
    p = np.asarray(p_mm, float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise ValueError(f"expected attained positions of shape (n >= 2, 3), got {p.shape}")
    return p


def rp_uncertainty_mm(p_mm: np.ndarray) -> float:
    """Jackknife standard uncertainty (mm) of the RP of attained positions ``p_mm`` (n >= 3, 3): the spread of the
    n leave-one-cycle-out RPs, ``sqrt((n - 1) / n * sum((RP_(i) - mean)^2))``."""
    p = _positions(p_mm)
    n = len(p)
    if n < 3:
        raise ValueError(f"the RP's uncertainty needs at least 3 cycles, got {n}")
    keep = ~np.eye(n, dtype=bool)
    l_mean, s_l = _l_stats(np.broadcast_to(p, (n, n, 3))[keep].reshape(n, n - 1, 3))
    rp = l_mean + 3.0 * s_l
    return float(np.sqrt((n - 1) / n * np.sum((rp - rp.mean()) ** 2)))


def tracker_rp_mm(cov_tracker_mm2: np.ndarray) -> float:
    """The RP the tracker's noise alone gives (mm): ``RP_PER_SIGMA * sqrt(trace / 3)`` of its covariance (3, 3)
    mm^2 (or the mean trace of (m, 3, 3)), the isotropic scatter with the same mean squared spread."""
    cov = np.asarray(cov_tracker_mm2, float).reshape(-1, 3, 3)
    return float(RP_PER_SIGMA * np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2)) / 3.0))


def robot_rp_mm(rp_mm, rp_tracker_mm: float):
    """The robot's RP (mm) with the tracker's removed in quadrature: ``sqrt(max(RP^2 - RP_tracker^2, 0))``."""
    return np.sqrt(np.maximum(np.square(rp_mm) - rp_tracker_mm ** 2, 0.0))


def split_rp(p_mm: np.ndarray, cov_tracker_mm2: np.ndarray, k: float = COVERAGE_K) -> RepeatabilitySplit:
    """The measured RP of ``p_mm`` (n >= 3, 3) split into the tracker's share (covariance (3, 3) mm^2 at the
    pose) and the robot's, with the robot's interval from ``RP -+ k u(RP)`` (see the module doc)."""
    pc = pose_characteristics(p_mm, np.zeros(3))
    u = rp_uncertainty_mm(p_mm)
    rp_t = tracker_rp_mm(cov_tracker_mm2)
    low, mid, high = robot_rp_mm(np.maximum([pc.rp_mm - k * u, pc.rp_mm, pc.rp_mm + k * u], 0.0), rp_t)
    return RepeatabilitySplit(pc.rp_mm, u, rp_t, float(mid), float(low), float(high), float(k))


def distance_characteristics(p1_mm: np.ndarray, p2_mm: np.ndarray, c1_mm: np.ndarray, c2_mm: np.ndarray,
                             poses: tuple[str, str] = ("P2", "P4")) -> DistanceCharacteristics:
    """AD and RD between poses measured in the same cycles: ``p1_mm``, ``p2_mm`` (n, 3); commanded (3,)."""
    p1, p2 = np.asarray(p1_mm, float), np.asarray(p2_mm, float)
    if p1.shape != p2.shape or p1.ndim != 2 or p1.shape[1] != 3 or len(p1) < 2:
        raise ValueError(f"expected two (n >= 2, 3) arrays of the same shape, got {p1.shape} and {p2.shape}")
    dc = np.asarray(c1_mm, float) - np.asarray(c2_mm, float)
    d = np.linalg.norm(p1 - p2, axis=1)
    ad_axis = (p1 - p2).mean(axis=0) - dc
    return DistanceCharacteristics(tuple(poses), len(d), float(np.linalg.norm(dc)), float(d.mean()),
                                   float(d.mean() - np.linalg.norm(dc)), float(ad_axis[0]), float(ad_axis[1]),
                                   float(ad_axis[2]), float(3.0 * np.std(d, ddof=1)))


def largest_cube(center_mm, size_mm) -> tuple[np.ndarray, float]:
    """Centre (3,) and edge (mm) of the largest cube, edges parallel to the axes, inside a box."""
    return np.asarray(center_mm, float), float(np.min(size_mm))


def cube_poses(center_mm, edge_mm: float) -> np.ndarray:
    """P1..P5 (5, 3) mm on the diagonal plane through the cube's edges at (y, z) = (-h, -h) and (+h, +h)."""
    h = edge_mm / 2.0
    corners = np.array([[-h, -h, -h], [h, -h, -h], [h, h, h], [-h, h, h]])     # C1, C2, C7, C8
    return np.vstack([np.zeros(3), (1.0 - 2.0 * CORNER_FRACTION) * corners]) + np.asarray(center_mm, float)


def characteristics(p_by_pose_mm: np.ndarray, p_cmd_mm: np.ndarray, pose_names=POSE_NAMES,
                    distance_pair: tuple[int, int] = (1, 3)) -> tuple[list[PoseCharacteristics], DistanceCharacteristics]:
    """Every pose's AP/RP and the distance characteristics between ``distance_pair`` (default P2-P4).

    ``p_by_pose_mm`` (P, n, 3): attained positions per pose and cycle; ``p_cmd_mm`` (P, 3)."""
    p = np.asarray(p_by_pose_mm, float)
    poses = [pose_characteristics(p[j], p_cmd_mm[j], pose_names[j]) for j in range(len(p))]
    a, b = distance_pair
    dist = distance_characteristics(p[a], p[b], p_cmd_mm[a], p_cmd_mm[b], (pose_names[a], pose_names[b]))
    return poses, dist
