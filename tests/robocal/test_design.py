"""Optimal design numerics: rank-3 updates against direct algebra, greedy/exchange against brute force, the
joint spread, the tour, the learning-curve prediction against simulated refits, and the forecast against
Monte-Carlo calibrations."""
import itertools

import numpy as np
import pytest

from robocal.design.optimal import (_Design, blocked_cv, criterion, d_optimal, farthest_first, forecast, greedy_order,
                            move_cost, predict_rms, short_tour, space_filling, whiten_rows)
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.kinematics.models import ParamLayout, smr_tracker
from robocal.design.pool import incidence_rad, tilted_rotations, wrist_flipped
from robocal.kinematics.models import fk
from tests.cells import irb2600, irb2600_poses, make_cell, measure



def _logdet(A, idx):
    L = A.shape[2]
    flat = A[list(idx)].reshape(-1, L)
    return np.linalg.slogdet(np.eye(L) + flat.T @ flat)[1]


@pytest.mark.unit
def test_rank3_updates_match_the_direct_inverse():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(40, 3, 7))
    d = _Design(A)
    for k in (3, 17, 5, 30):
        d.add(k)
    d.remove(17)
    M = np.eye(7) + sum(A[k].T @ A[k] for k in (3, 5, 30))
    np.testing.assert_allclose(d.Minv, np.linalg.inv(M), atol=1e-10)
    S = np.einsum("mil,lk,mjk->ijm", A, np.linalg.inv(M), A)
    np.testing.assert_allclose(d.S, S, atol=1e-10)
    gain = d.gains()[8]
    assert gain == pytest.approx(_logdet(A, (3, 5, 30, 8)) - _logdet(A, (3, 5, 30)))


@pytest.mark.unit
def test_d_optimal_finds_the_brute_force_optimum_of_a_small_problem():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(12, 3, 5)) * rng.uniform(0.2, 2.0, (12, 1, 1))
    best = max(itertools.combinations(range(12), 3), key=lambda c: _logdet(A, c))
    res = d_optimal(A, 3)
    assert set(res.chosen) == set(best)
    assert res.logdet == pytest.approx(_logdet(A, best))


@pytest.mark.unit
def test_d_optimal_beats_random_designs_and_orders_by_gain():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(600, 3, 20)) * rng.uniform(0.1, 1.0, (600, 1, 1))
    res = d_optimal(A, 40)
    assert len(set(res.chosen)) == 40
    rand = [_logdet(A, rng.choice(600, 40, replace=False)) for _ in range(20)]
    assert res.logdet > max(rand)
    # the order is greedy: every prefix of 10 beats random sets of 10
    assert _logdet(A, res.chosen[:10]) > max(_logdet(A, rng.choice(600, 10, replace=False)) for _ in range(20))


@pytest.mark.unit
def test_spread_fills_each_joint_range_at_every_prefix():
    """One joint, the information growing with |q|: pure D-optimality piles up at the ends; with the spread
    constraint the (t+1)-th point always lands in a bin of t + 1 equal-count bins that the first t left empty,
    so every prefix covers the range (no gap beyond 4 x the even spacing)."""
    q = np.linspace(-1.0, 1.0, 400)
    A = (np.abs(q)[:, None, None] + 0.1) * np.random.default_rng(3).normal(size=(400, 3, 4))
    plain = greedy_order(A, 20)
    spread = greedy_order(A, 20, spread=q[:, None])
    assert np.mean(np.abs(q[plain]) > 0.8) > 0.6
    for t in range(20):
        bins = (np.argsort(np.argsort(q)) * (t + 1)) // 400
        assert bins[spread[t]] not in set(bins[spread[:t]])
    for n in (5, 10, 20):
        edges = np.concatenate([[-1.0], np.sort(q[spread[:n]]), [1.0]])
        assert np.max(np.diff(edges)) <= 4.0 * 2.0 / n
        assert np.max(np.diff(np.concatenate([[-1.0], np.sort(q[plain[:n]]), [1.0]]))) > 0.8


@pytest.mark.unit
def test_short_tour_is_a_shorter_permutation():
    rng = np.random.default_rng(4)
    q = rng.uniform(-2, 2, (150, 6))
    start = np.zeros(6)
    order = short_tour(q, start)
    assert sorted(order) == list(range(150))
    tour = move_cost(q[order[:-1]], q[order[1:]]).sum()
    assert tour < 0.5 * move_cost(q[:-1], q[1:]).sum()
    assert order[0] == int(np.argmin(move_cost(start, q)))


@pytest.mark.unit
def test_pool_geometry():
    R0 = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))[0]
    R0 *= np.sign(np.linalg.det(R0))
    Rs = tilted_rotations(R0, np.radians(20), 6)
    assert len(Rs) == 7
    np.testing.assert_allclose(np.einsum("kji,kjl->kil", Rs, Rs), np.broadcast_to(np.eye(3), (7, 3, 3)), atol=1e-12)
    tilt = np.degrees(np.arccos(np.clip(Rs[:, :, 2] @ R0[:, 2], -1, 1)))
    np.testing.assert_allclose(tilt, [0] + [20] * 6, atol=1e-9)
    R = np.broadcast_to(np.eye(3), (2, 3, 3))              # SMR axis +z
    inc = incidence_rad(R, np.array([[0, 0, 0], [0, 0, 0.0]]), [0.0, 1000.0, 1000.0])
    np.testing.assert_allclose(np.degrees(inc), 45.0)
    kin = irb2600()                                        # spherical wrist: the flipped solution is the same pose
    q = np.radians([[10, 20, -30, 40, 50, 60], [-30, 10, 5, -100, -40, 170]])
    np.testing.assert_allclose(fk(kin, wrist_flipped(q)), fk(kin, q), atol=1e-9)


@pytest.mark.system                 # a Monte-Carlo study (many calibrations)
def test_forecast_std_matches_monte_carlo_calibrations():
    kin = irb2600()
    qc, qt = irb2600_poses()
    qc = qc[::3]
    rng = np.random.default_rng(6)
    cell = make_cell(kin, rng)
    kin_t = kin.with_(T_tracker_base=cell.truth.T_tracker_base)
    _, cov = measure(cell, qc, rng)
    _, cov_t = measure(cell, qt, rng)
    fc = forecast(kin_t, qc, cov, qt, cov_t)
    deltas, errs = [], []
    for _ in range(25):
        p, cov = measure(cell, qc, rng)
        res = calibrate(kin, qc, p, cov, CalibrationOptions(method="lm"))
        layout = ParamLayout.of(res.kinematics)
        deltas.append([res.delta[layout.index(n)] for n in ("a2", "d4", "theta2", "alpha1")])
        errs.append(np.sum((cell.true_smr_tracker(qt) - smr_tracker(res.kinematics, qt)) ** 2, axis=1).mean())
    mc = np.std(deltas, axis=0)
    want = np.array([fc.std[fc.names.index(n)] for n in ("a2", "d4", "theta2", "alpha1")])
    np.testing.assert_allclose(mc, want, rtol=0.45)
    assert np.sqrt(np.mean(errs)) == pytest.approx(fc.model_rms_mm, rel=0.35)


@pytest.mark.unit
def test_predicted_curve_matches_simulated_refits():
    """A linear model y = G x + noise: the predicted held-out RMS of the fit on the first n points against the
    RMS of actual fits on n points judged on fresh test points; blocked CV finds no unmodelled part here and
    finds it when a smooth term is left out of the model."""
    rng = np.random.default_rng(7)
    N, P, T = 300, 12, 200
    G, Jt = rng.normal(size=(N, 3, P)), rng.normal(size=(T, 3, P))
    H = np.einsum("tip,tiq->pq", Jt, Jt) / T
    n_points = np.array([40, 100, 300])
    pred = predict_rms(G, n_points, H, np.sqrt(3.0), 0.0, 1.0)
    x = rng.normal(size=P)
    got = []
    for n in n_points:
        se = []
        for _ in range(200):
            y = G[:n] @ x + rng.normal(size=(n, 3))
            xh = np.linalg.lstsq(G[:n].reshape(-1, P), y.reshape(-1), rcond=None)[0]
            se.append(np.mean(np.sum((Jt @ x + rng.normal(size=(T, 3)) - Jt @ xh) ** 2, axis=1)))
        got.append(np.sqrt(np.mean(se)))
    np.testing.assert_allclose(pred, got, rtol=0.03)
    cov = np.broadcast_to(np.eye(3), (N, 3, 3))
    y = G @ x + rng.normal(size=(N, 3))
    r = y - G @ np.linalg.lstsq(G.reshape(-1, P), y.reshape(-1), rcond=None)[0]
    se, var = blocked_cv(whiten_rows(G, cov), r, G, r)
    assert np.mean(se) - 3.0 - np.mean(var) == pytest.approx(0.0, abs=0.35)
    bias = 1.5 * np.sin(np.linspace(0, 6, N))[:, None] * np.ones(3)
    y2 = y + bias
    r2 = y2 - G @ np.linalg.lstsq(G.reshape(-1, P), y2.reshape(-1), rcond=None)[0]
    se2, var2 = blocked_cv(G, r2, G, r2)
    assert np.mean(se2) - 3.0 - np.mean(var2) > 1.0


def _irb2600_criterion():
    """(kinematics, calibration poses, their criterion) of the IRB 2600 test cell, 1e-3 mm^2 per axis."""
    kin = irb2600()
    qc, _ = irb2600_poses()
    return kin, qc, criterion(kin, qc, np.broadcast_to(np.eye(3) * 1e-3, (len(qc), 3, 3)))


@pytest.mark.system
def test_criterion_counts_the_parameters_a_pose_set_identifies():
    kin, qc, c = _irb2600_criterion()
    layout = ParamLayout.of(kin)
    assert c.A.shape == (len(qc), 3, len(c.names)) and c.names[: layout.size] == layout.names
    assert any(n.startswith("joint_compliance") for n in c.names) and any(n.startswith("gear_cyclic") for n in c.names)
    assert layout.size - 12 < c.identifiable < len(c.names)       # theta1, d1, the J6 terms, ... are not
    assert c.spread.shape == (len(qc), 3)                          # the major axes J1-J3


@pytest.mark.unit
def test_farthest_first_takes_the_farthest_point_at_every_step():
    X = np.random.default_rng(2).normal(size=(200, 3))
    chosen = farthest_first(X, 25)
    assert len(set(chosen.tolist())) == 25
    assert chosen[0] == np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1))
    for t in range(1, 25):                          # brute force: the largest distance to the points chosen before
        d = np.min(np.linalg.norm(X[:, None] - X[chosen[:t]][None], axis=2), axis=1)
        assert d[chosen[t]] == pytest.approx(d.max())


@pytest.mark.system
def test_space_filling_keeps_the_geometry_determined_or_falls_back_to_d_optimal():
    from dataclasses import replace
    kin, qc, c = _irb2600_criterion()
    chosen, filled = space_filling(kin, c, qc, 60)
    assert filled
    np.testing.assert_array_equal(chosen, farthest_first(qc * c.levers_mm_per_rad, 60))
    stricter = replace(c, identifiable_geometric=c.identifiable_geometric + 1)    # more than any subset determines
    chosen, filled = space_filling(kin, stricter, qc, 60)
    assert not filled
    np.testing.assert_array_equal(chosen, d_optimal(c.A, 60, c.spread).chosen)
