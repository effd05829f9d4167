"""ISO 9283 formulas on synthetic data whose answers are worked out by hand (numbers in the comments)."""
import numpy as np
import pytest

from robocal.iso9283 import (characteristics, cube_poses, distance_characteristics, largest_cube,
                             pose_characteristics)
from robocal.noise import RP_PER_SIGMA

pytestmark = pytest.mark.unit


def test_pose_accuracy_and_repeatability_hand_computed():
    # attained = commanded + offset + 6 points: +-1 on x, +-1 on y, +-4 on z  -> barycentre = commanded + offset
    cmd = np.array([1000.0, -200.0, 800.0])
    offset = np.array([0.3, -0.4, 1.2])                        # |offset| = 1.3
    spread = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 4], [0, 0, -4]], float)
    pc = pose_characteristics(cmd + offset + spread, cmd, "P1")
    assert pc.ap_mm == pytest.approx(1.3, abs=1e-12)
    assert (pc.apx_mm, pc.apy_mm, pc.apz_mm) == pytest.approx((0.3, -0.4, 1.2), abs=1e-12)
    # l = 1,1,1,1,4,4: mean 2; deviations -1 x4, +2 x2 -> S_l = sqrt(12 / 5); RP = 2 + 3 sqrt(2.4) = 6.647580
    assert pc.l_mean_mm == pytest.approx(2.0)
    assert pc.s_l_mm == pytest.approx(np.sqrt(2.4))
    assert pc.rp_mm == pytest.approx(6.6475800154, abs=1e-9)


def test_distance_accuracy_and_repeatability_hand_computed():
    c1, c2 = np.zeros(3), np.array([100.0, 0.0, 0.0])
    p1 = np.zeros((4, 3))
    p2 = np.array([[100.0 + e, 0.0, 0.0] for e in (-1.0, 0.0, 1.0, 2.0)])
    d = distance_characteristics(p1, p2, c1, c2)
    # D = 99, 100, 101, 102: mean 100.5 -> AD = +0.5; S_D = sqrt(5 / 3) -> RD = 3 sqrt(5/3) = 3.872983
    assert d.distance_cmd_mm == pytest.approx(100.0)
    assert d.ad_mm == pytest.approx(0.5)
    assert d.adx_mm == pytest.approx(-0.5)                     # mean(x1 - x2) - (c1x - c2x) = -100.5 + 100
    assert (d.ady_mm, d.adz_mm) == pytest.approx((0.0, 0.0))
    assert d.rd_mm == pytest.approx(3.8729833462, abs=1e-9)


def test_rp_of_isotropic_gaussian_matches_maxwell_law():
    # l of an isotropic Gaussian is Maxwell distributed: mean 2 sqrt(2/pi) sigma, std sqrt(3 - 8/pi) sigma
    rng = np.random.default_rng(3)
    sigma = 0.02
    pc = pose_characteristics(rng.normal(0, sigma, (200_000, 3)), np.zeros(3))
    assert pc.rp_mm == pytest.approx(RP_PER_SIGMA * sigma, rel=0.01)
    assert pc.ap_mm < 1e-3


def test_cube_poses_on_the_diagonal_plane_at_a_tenth_of_the_diagonal():
    centre, edge = largest_cube([900, 0, 1000], [800, 1600, 1200])
    assert edge == 800 and tuple(centre) == (900, 0, 1000)
    P = cube_poses(centre, edge)
    h = edge / 2
    corners = centre + np.array([[-h, -h, -h], [h, -h, -h], [h, h, h], [-h, h, h]])
    L = np.linalg.norm(corners[2] - corners[0])                # diagonal of the plane: edge * sqrt(3)
    assert L == pytest.approx(edge * np.sqrt(3))
    assert np.allclose(P[0], centre)
    for k in range(4):
        assert np.linalg.norm(P[1 + k] - corners[k]) == pytest.approx(0.1 * L)
    # all five on the plane y - z = 0 (relative to the centre), inside the cube
    rel = P - centre
    assert np.allclose(rel[:, 1], rel[:, 2])
    assert np.all(np.abs(rel) <= h)
    # P2-P4 and P3-P5 are the two diagonals through the centre
    assert np.allclose(P[1] + P[3], 2 * centre) and np.allclose(P[2] + P[4], 2 * centre)


def test_characteristics_over_poses():
    rng = np.random.default_rng(0)
    cmd = cube_poses([0, 0, 0], 100.0)
    p = cmd[:, None, :] + np.array([0.1, 0, 0]) + rng.normal(0, 0.01, (5, 30, 3))
    poses, dist = characteristics(p, cmd)
    assert [pc.pose for pc in poses] == ["P1", "P2", "P3", "P4", "P5"]
    assert all(abs(pc.apx_mm - 0.1) < 0.01 for pc in poses)
    assert dist.poses == ("P2", "P4") and abs(dist.ad_mm) < 0.01


def test_rejects_bad_shapes():
    with pytest.raises(ValueError):
        pose_characteristics(np.zeros((1, 3)), np.zeros(3))
    with pytest.raises(ValueError):
        distance_characteristics(np.zeros((3, 3)), np.zeros((4, 3)), np.zeros(3), np.zeros(3))
