"""The one owner of the approach sign and of the noise floor from repeated poses, against plain references."""
from __future__ import annotations

import numpy as np
import pytest

from robocal.measure.approach import approach_signs, next_approach
from robocal.measure.repeats import noise_floor_from_repeats, repeat_dof, repeat_groups


def _approach_loop(q, tol):
    out = np.zeros_like(q)
    for i in range(1, len(q)):
        for j in range(q.shape[1]):
            d = q[i, j] - q[i - 1, j]
            out[i, j] = np.sign(d) if abs(d) > tol else out[i - 1, j]
    return out


@pytest.mark.unit
@pytest.mark.parametrize("tol", [0.0, 0.75])
def test_approach_signs_equal_a_loop_and_the_runner_rule(tol):
    rng = np.random.default_rng(4)
    q = np.round(rng.uniform(-10, 10, (50, 6)), 0)
    q[10:13, 2] = q[9, 2]                       # a joint that does not move keeps its sign
    expected = _approach_loop(q, tol)
    np.testing.assert_array_equal(approach_signs(q, tol), expected)
    signs, prev = None, None
    for i, row in enumerate(q):                 # the runner applies the same rule one stop at a time
        signs = next_approach(signs, prev, row, tol)
        prev = row
        np.testing.assert_array_equal(signs, expected[i])


@pytest.mark.unit
def test_noise_floor_from_repeats_is_the_pooled_within_pose_deviation():
    rng = np.random.default_rng(5)
    poses = rng.uniform(-50, 50, (6, 6))
    q = np.repeat(poses, 4, axis=0)[rng.permutation(24)]
    p = rng.normal(0, 0.02, (24, 3))
    ss, dof = 0.0, 0
    for pose in poses:                          # reference: group by exact pose, pool the variance
        rows = np.all(q == pose, axis=1)
        ss += np.sum((p[rows] - p[rows].mean(axis=0)) ** 2)
        dof += rows.sum() - 1
    assert noise_floor_from_repeats(q, p) == pytest.approx(np.sqrt(ss / dof))
    assert repeat_dof(q) == dof == 18
    assert sorted(len(g) for g in repeat_groups(q)) == [4] * 6
    assert noise_floor_from_repeats(q[:3], p[:3]) is None
