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


def _campaign(n, seed=0):
    """A geometric-error robot measured at n poses (mm, noise 0.02 mm) and a few gross faults."""
    from robocal.kinematics.models import apply_update, ParamLayout, smr_tracker
    rng = np.random.default_rng(seed)
    truth = apply_update(KIN, rng.normal(0, 1e-3, ParamLayout.of(KIN).size))
    q = _poses(n, seed)
    p = smr_tracker(truth, q) + rng.normal(0, 0.02, (n, 3))
    p[::37] += 0.5
    return q, p


def test_identification_in_row_blocks_equals_one_block(monkeypatch):
    """The robust-ridge and LM identifications accumulate their normal equations, leverages and the triangular
    factor of the identifiability analysis over row blocks: the same answer as one block (to the rounding that the
    convergence test, |dx| < 1e-7, leaves)."""
    from robocal.identify import identification as identify
    q, p = _campaign(300)
    cov = np.broadcast_to(np.diag([4e-4, 5e-4, 6e-4]), (len(q), 3, 3))
    opts = [identify.CalibrationOptions(), identify.CalibrationOptions(method="lm")]
    one = [identify.calibrate(KIN, q, p, cov, o) for o in opts]
    monkeypatch.setattr(identify, "DESIGN_ROWS", 64)
    blocked = [identify.calibrate(KIN, q, p, cov, o) for o in opts]
    for a, b in zip(one, blocked):
        assert a.identified == b.identified and a.iterations == b.iterations
        np.testing.assert_allclose(b.point_weights, a.point_weights, atol=1e-6)
        np.testing.assert_array_equal(b.point_weights == 0, a.point_weights == 0)
        np.testing.assert_allclose(b.delta, a.delta, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(b.std, a.std, rtol=1e-6)
        assert b.condition_number == pytest.approx(a.condition_number, rel=1e-9)
    assert (one[0].point_weights == 0).sum() >= 5            # the faults were rejected (the weights matter)


def test_tool_registration_in_row_blocks_equals_one_block(monkeypatch):
    from robocal.identify import identification as identify
    q, p = _campaign(300, seed=2)
    one = identify.register_tool(KIN, q, p, KIN.p_flange_smr_mm + [1.0, -2.0, 3.0])
    monkeypatch.setattr(identify, "DESIGN_ROWS", 50)
    blocked = identify.register_tool(KIN, q, p, KIN.p_flange_smr_mm + [1.0, -2.0, 3.0])
    assert blocked.determined == one.determined
    np.testing.assert_allclose(blocked.T_tracker_base, one.T_tracker_base, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(blocked.p_flange_smr_mm, one.p_flange_smr_mm, atol=1e-9)
    np.testing.assert_allclose(blocked.weights, one.weights, atol=1e-9)


def test_elastic_fit_and_effects_in_row_blocks_equal_one_block(monkeypatch):
    """The joint fit of geometry and effects sums its normal equations over row blocks and the effects' state is
    computed per block; a warm-up from logged temperatures keeps the first row's temperature as its reference."""
    from robocal.effects import bases as effects, fit as elastic_fit
    from robocal.effects.fit import calibrate_elastic
    from robocal.effects.model import EffectChoice, elastic_smr_tracker
    from robocal.kinematics.models import ParamLayout
    rng = np.random.default_rng(4)
    q = _poses(300, seed=4)
    meta = {"payload_kg": np.full(len(q), 10.0), "temp_c": 20.0 + np.linspace(0.0, 3.0, len(q)),
            "t_s": np.arange(len(q)) * 10.0}
    choices = [EffectChoice("joint_compliance", (("joints", (2, 3)),)), EffectChoice("gear_cyclic", (("joint", 1),)),
               EffectChoice("thermal_drift", (("tau_s", 1800.0), ("joints", (2,))))]
    truth = [(c.build(6), np.array(v)) for c, v in zip(choices, ([4e-7, 9e-7], [3e-5, -2e-5, 1e-5, 1e-5],
                                                                 [1e-4, 5e-5]))]
    p = elastic_smr_tracker(KIN, q, meta, truth) + rng.normal(0, 0.01, (len(q), 3))
    cols = np.array([ParamLayout.of(KIN).index(n) for n in ("a2", "a3", "d4", "base_tx", "base_ty", "base_tz",
                                                            "base_rx", "base_ry", "base_rz", "tool_z")])
    one = calibrate_elastic(KIN, cols, q, p, None, meta, choices)
    state = effects.effect_state(KIN, q, meta, truth)
    monkeypatch.setattr(elastic_fit, "DESIGN_ROWS", 64)
    monkeypatch.setattr(effects, "EFFECT_ROWS", 50)
    blocked = calibrate_elastic(KIN, cols, q, p, None, meta, choices)
    for a, b in zip(state, effects.effect_state(KIN, q, meta, truth)):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-15)
    for a, b in zip(one.effects, blocked.effects):
        np.testing.assert_allclose(b.values, a.values, rtol=1e-7)
        np.testing.assert_allclose(b.std, a.std, rtol=1e-6)
    assert blocked.sigma0 == pytest.approx(one.sigma0, rel=1e-9) and blocked.iterations == one.iterations
    np.testing.assert_allclose(blocked.residual_tracker_mm, one.residual_tracker_mm, atol=1e-9)


def test_blocked_cv_built_from_row_blocks_keeps_float64_fits_and_float32_columns():
    """``BlockedCV.of_blocks``: the design whitened and added to the folds' Gram matrices block by block (fits:
    the whole-design numbers to rounding), the columns kept in float32 (held-out errors to ~1e-7 of the size of
    the predictions they are the difference of)."""
    rng = np.random.default_rng(3)
    N, P = 90, 6
    A = rng.normal(size=(N, 3, P)) * [1.0, 10.0, 0.1, 1.0, 100.0, 1.0]
    y = A @ rng.normal(size=P) + rng.normal(0, 0.1, (N, 3))
    W = np.linalg.inv(np.tril(rng.normal(0, 0.1, (N, 3, 3))) + np.eye(3))
    blockings = [Blocking("pose", pose_blocks(rng.normal(size=(N, 6)), 4, seed=1)),
                 Blocking("order", np.arange(N) * 4 // N)]
    one = BlockedCV(A, y, W, blockings)
    blocks = [(slice(s, min(s + 13, N)), A[s:s + 13], y[s:s + 13]) for s in range(0, N, 13)]
    built = BlockedCV.of_blocks(iter(blocks), N, P, W, blockings)
    assert built.Aw.dtype == np.float32
    np.testing.assert_allclose(built.Aw, one.Aw, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(built.scale, one.scale, rtol=1e-12)
    for cols in ([0, 1, 2], [0, 2, 4, 5], list(range(P))):
        np.testing.assert_allclose(built.fit(cols), one.fit(cols), rtol=1e-9)
        for i in range(len(blockings)):
            err = one.errors(cols, i)
            assert np.abs(built.errors(cols, i) - err).max() < 1e-6 * np.abs(y - err).max()
    np.testing.assert_allclose(built.absorbed([4, 5], [0, 1]), one.absorbed([4, 5], [0, 1]), rtol=1e-9)
