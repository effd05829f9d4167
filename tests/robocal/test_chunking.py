"""Row-blocked computations (bounded memory at 10^5 poses) give the numbers of the one-block computation: every
block size is forced down to a few rows on small seeded data and compared with the default (one block)."""
import numpy as np
import pytest

from robocal.identify import screening as screen
from robocal.kinematics import models as kinematics
from robocal.layers import gp
from robocal.effects.cv import BlockedCV, Blocking, design_array, pose_blocks
from robocal.effects import cv
from robocal.simulation.truth_cell import irb2600_nominal

pytestmark = pytest.mark.unit
KIN = irb2600_nominal()


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    return np.radians(rng.uniform(-60, 60, (n, 6)))


def test_identification_jacobian_in_row_blocks_equals_one_block(monkeypatch):
    q = _poses(50)
    p1, J1 = kinematics.identification_jacobian(KIN, q)
    p1t, Jt1 = kinematics.identification_jacobian_t(KIN, q)
    monkeypatch.setattr(kinematics, "JACOBIAN_ROWS", 7)
    p2, J2 = kinematics.identification_jacobian(KIN, q)
    p2t, Jt2 = kinematics.identification_jacobian_t(KIN, q)
    np.testing.assert_array_equal(p1, p2)
    np.testing.assert_array_equal(J1, J2)
    np.testing.assert_array_equal(p1t, p2t)
    np.testing.assert_array_equal(Jt1, Jt2)
    np.testing.assert_array_equal(J1, Jt1.transpose(1, 2, 0))


def test_frames_only_chain_in_row_blocks_equals_one_block(monkeypatch):
    """Per-pose DH overrides (links scaled per pose, as thermal growth does) are sliced with the rows."""
    q = _poses(40)
    scale = 1.0 + np.linspace(-1e-4, 1e-4, len(q))[:, None]
    kw = dict(a=KIN.a_mm * scale, d=KIN.d_mm * scale, full=False)
    one = kinematics.chain(KIN, q, **kw)
    monkeypatch.setattr(kinematics, "CHAIN_ROWS", 7)
    blocked = kinematics.chain(KIN, q, **kw)
    for a, b in zip(one[:3], blocked[:3]):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(kinematics.fk(KIN, q), kinematics.chain(KIN, q, full=True).T_base_flange)


def test_screen_in_row_blocks_equals_one_block(monkeypatch):
    """Clustered poses (neighbours exist) with a few faults: the same neighbours, scores and exclusions."""
    rng = np.random.default_rng(1)
    q = np.radians(np.array([0, 20, -10, 0, 45, 0]) + rng.uniform(-5, 5, (80, 6)))
    p = kinematics.smr_base(KIN, q)
    r = rng.normal(0, 0.02, (len(q), 3))
    r[[3, 40]] += [1.5, 0.0, 0.0]
    lever, near = screen.joint_levers_mm(KIN, q), 0.13 * screen.reach_mm(KIN)
    one = screen.screen(q, p, r, lever, near)
    idx1, valid1 = screen.near_neighbours(q, p, lever, near)
    monkeypatch.setattr(screen, "CHUNK_ROWS", 6)
    blocked = screen.screen(q, p, r, lever, near)
    idx2, valid2 = screen.near_neighbours(q, p, lever, near)
    np.testing.assert_array_equal(idx1, idx2)
    np.testing.assert_array_equal(valid1, valid2)
    np.testing.assert_array_equal(one.z_local, blocked.z_local)
    np.testing.assert_array_equal(one.keep, blocked.keep)
    assert [e.index for e in one.excluded] == [e.index for e in blocked.excluded] and one.excluded
    given = screen.screen(q, p, r, None, near, neighbours=(idx1, valid1))     # the search done once, passed in
    np.testing.assert_array_equal(one.z_local, given.z_local)
    assert [e.reason for e in one.excluded] == [e.reason for e in given.excluded]


def test_blocked_cv_in_row_blocks_equals_one_block(monkeypatch):
    rng = np.random.default_rng(2)
    N, P = 90, 6
    A = rng.normal(size=(N, 3, P))
    y = A @ rng.normal(size=P) + rng.normal(0, 0.1, (N, 3))
    L = np.tril(rng.normal(0, 0.1, (N, 3, 3))) + np.eye(3)
    W = np.linalg.inv(L)
    blockings = [Blocking("pose", pose_blocks(rng.normal(size=(N, 6)), 4, seed=1)),
                 Blocking("order", np.arange(N) * 4 // N)]
    one = BlockedCV(A, y, W, blockings)
    monkeypatch.setattr(cv, "CHUNK_ROWS", 7)
    A2 = design_array(N, P)
    A2[...] = A
    blocked = BlockedCV(A2, y, W, blockings, copy=False)          # whitened in place, in blocks of 7 rows
    assert np.shares_memory(blocked.Aw, A2)
    row_major = BlockedCV(A.copy(), y, W, blockings, copy=False)     # not parameter-major: copied, same numbers
    np.testing.assert_array_equal(one.Aw, row_major.Aw)
    np.testing.assert_array_equal(one.Aw, blocked.Aw)
    for cols in ([0, 1, 2], [0, 2, 4, 5], list(range(P))):
        for i in range(len(blockings)):
            np.testing.assert_array_equal(one.errors(cols, i), blocked.errors(cols, i))
        np.testing.assert_array_equal(one.fit(cols), blocked.fit(cols))


def test_gp_predictions_in_row_blocks_equal_one_block(monkeypatch):
    rng = np.random.default_rng(3)
    X = rng.uniform(-1, 1, (40, 3))
    g = gp.GaussianProcess(X, np.sin(X @ [1.0, 2.0, -1.0]) + rng.normal(0, 0.01, 40), 1.0, 0.05,
                           np.array([0.7, 0.9, 1.2]), x_centre=X.mean(axis=0))
    multi = gp.MultiOutputGP((g, gp.GaussianProcess(X, X[:, 0] ** 2, 2.0, 0.05, g.length, x_centre=g.x_centre)))
    Xs = rng.uniform(-1, 1, (33, 3))
    mean1, var1 = g.predict(Xs, return_var=True)
    out1 = multi.predict(Xs)
    monkeypatch.setattr(gp, "KERNEL_BLOCK_BYTES", 8 * 40 * 4)      # 4 test rows per block
    assert len(gp.kernel_blocks(len(Xs), len(X))) == 9
    mean2, var2 = g.predict(Xs, return_var=True)
    np.testing.assert_allclose(mean2, mean1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(var2, var1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(multi.predict(Xs), out1, rtol=0, atol=1e-12)
