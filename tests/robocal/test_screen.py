"""The measurement-fault screens of robocal.identify.screening on synthetic data: near neighbours only, SMR triangle, nests."""
import numpy as np
import pytest

from robocal.kinematics.models import Kinematics
from robocal.multi_smr.calibration import predict_multi
from robocal.measure.noise import TrackerUncertainty
from robocal.identify.screening import joint_levers_mm, nest_misreads, reach_mm, screen, smr_triangle
from robocal.simulation.truth_cell import irb2600_nominal

pytestmark = pytest.mark.unit
KIN = irb2600_nominal()
OFFSETS = np.array([[0.36, 0.28, 39.43], [90.0, 0.0, 50.0], [0.0, 90.0, 50.0]])


def _cluster(rng, centre_deg, n, spread_deg):
    return np.radians(centre_deg + rng.uniform(-spread_deg, spread_deg, (n, 6)))


def test_a_residual_is_judged_against_near_neighbours_only():
    """A dense cluster with one 2 mm fault and a far pose (J1 120 deg away) with a 2 mm residual: the fault is
    excluded, the far pose is not (nothing is near it), and its missing neighbourhood is reported."""
    rng = np.random.default_rng(0)
    q = np.vstack([_cluster(rng, np.array([0, 20, -10, 0, 45, 0]), 60, 4.0), np.radians([[120, 20, -10, 0, 45, 0]])])
    p = np.asarray(__import__("robocal.kinematics", fromlist=["smr_base"]).smr_base(KIN, q))
    r = rng.normal(0, 0.02, (len(q), 3))
    r[5] += [2.0, 0.0, 0.0]
    r[-1] += [0.0, 2.0, 0.0]
    sc = screen(q, p, r, joint_levers_mm(KIN, q), 0.13 * reach_mm(KIN))
    assert [e.index for e in sc.excluded] == [5] and "near neighbours" in sc.excluded[0].reason
    assert sc.n_near[-1] == 0 and np.isnan(sc.z_local[-1]) and sc.keep[-1]


def test_neighbours_in_another_configuration_are_not_near():
    """Same SMR position, wrist flipped and J1 on the other side of the base axis: near in position, far in joint
    motion (the levers of J1-J3 are long)."""
    from robocal.identify.screening import near_neighbours
    q = np.radians([[0, 20, -10, 0, 45, 0], [0, 20, -10, 0, 45, 1], [0, 21, -10, 0, 45, 0], [0, 20, -11, 0, 45, 0],
                    [0, 20, -10, 1, 45, 0], [100, 20, -10, 0, 45, 0]])
    p = np.zeros((len(q), 3))                                 # all at the same position: only joints tell them apart
    idx, valid = near_neighbours(q, p, joint_levers_mm(KIN, q), 300.0)
    near_of_0 = set(idx[0][valid[0]].tolist())
    assert near_of_0 == {1, 2, 3, 4}


def _three_smr_poses(seed, n=200):
    rng = np.random.default_rng(seed)
    q = rng.uniform(np.radians([-60, -40, -60, -120, -100, -180]), np.radians([60, 70, 40, 120, 100, 180]), (n, 6))
    truth = KIN.with_(T_tracker_base=np.array([[1, 0, 0, -3000.0], [0, 1, 0, 500], [0, 0, 1, -800], [0, 0, 0, 1]]))
    P = predict_multi(truth, OFFSETS, q)
    tr = TrackerUncertainty()
    noise = [np.einsum("nij,nj->ni", np.linalg.cholesky(tr.covariance(P[s])), rng.standard_normal((n, 3)))
             for s in range(3)]
    return rng, P + np.stack(noise), tr


def test_every_corrupted_smr_reading_is_caught_by_the_triangle():
    """Property over 20 seeds: 5 % of the poses get one SMR reading off by 1-3 mm in a random direction; the
    triangle test (tracker covariances as weights) flags exactly those poses and names the SMR."""
    caught = total = 0
    for seed in range(20):
        rng, P, tr = _three_smr_poses(seed)
        n = P.shape[1]
        rows = rng.choice(n, n // 20, replace=False)
        smr = rng.integers(0, 3, len(rows))
        d = rng.normal(size=(len(rows), 3))
        P[smr, rows] += d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(1.0, 3.0, (len(rows), 1))
        sc = smr_triangle(P, np.stack([tr.covariance(P[s]) for s in range(3)]))
        bad = np.zeros(n, bool)
        bad[rows] = True
        assert sc.rigid and np.array_equal(~sc.keep, bad), f"seed {seed}"
        named = [e for e in sc.excluded if "(SMR" in e.reason]
        assert all(f"(SMR {smr[list(rows).index(e.index)] + 1})" in e.reason for e in named)
        caught, total = caught + int(np.sum(~sc.keep & bad)), total + len(rows)
    print(f"triangle: {caught} of {total} corrupted SMR readings caught, no clean pose flagged")


def test_smrs_that_are_not_one_rigid_tool_are_refused():
    rng, P, _ = _three_smr_poses(1)
    P[2] = P[2][rng.permutation(P.shape[1])]               # SMR 3 of other poses
    sc = smr_triangle(P)
    assert not sc.rigid and "not on one rigid tool" in sc.why and ("d13" in sc.why or "d23" in sc.why)


def _nests(rng, m=300):
    t = np.arange(m) * 10.0
    nest = np.tile(np.arange(3), m // 3)
    base = np.array([[1000.0, 0, 0], [0, 2000, 0], [-500, -500, -800]])
    p = base[nest] + (t / 3000)[:, None] * [0.05, 0.02, 0.0] + rng.normal(0, 0.01, (m, 3))
    return t, nest, p


def test_nest_misreads_are_found_and_a_real_move_is_not():
    rng = np.random.default_rng(0)
    t, nest, p = _nests(rng)
    assert nest_misreads(t, nest, p).keep.all()
    p[[10, 100, 200]] += [[400, 0, 0], [0, 2, 0], [0, 0, 10.0]]
    p[150:] += (nest[150:] == 1)[:, None] * [0.5, 0, 0]         # nest 2 really moved half-way: a step, kept
    sc = nest_misreads(t, nest, p)
    assert [e.index for e in sc.excluded] == [10, 100, 200] and all("misread" in e.reason for e in sc.excluded)
