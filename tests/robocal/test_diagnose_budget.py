"""The error budget (robocal/diagnose/budget.py), the remainder's class (remainder.py) and the verdict on a
non-physical best description (gap.py): exact Shapley values, closure, bootstrap intervals, the records' JSON,
the shape of a noise excess, and two truth campaigns (joint jitter above the floor; a reach-dependent J2 sag
outside the library)."""
import math
from unittest import mock

import numpy as np
import pytest

import robocal.effects.select as select
from robocal.diagnose.core import diagnose
from robocal.diagnose.budget import BudgetTerms, ErrorBudget, error_budget, per_point, shapley
from robocal.diagnose.remainder import Remainder, noise_shape, nugget
from robocal.diagnose.selfcheck import truth_input
from robocal.simulation.truth_cell import TruthProtocol, simulate

SMALL = TruthProtocol(n_calib=200, n_test=80, check_poses=6, check_repeats=4, timestamps=False)


def _quadratic_game(rng, M=50, K=3):
    """Per-point squared error of the fields left: |sum_{k not in S} v_k + n|^2 (effects v (K, M, 3))."""
    v, n = rng.normal(size=(K, M, 3)), 0.1 * rng.normal(size=(M, 3))
    return v, n, lambda S: np.sum((v[[k for k in range(K) if k not in S]].sum(axis=0) + n) ** 2, axis=1)


@pytest.mark.unit
def test_shapley_of_a_quadratic_game_splits_the_cross_terms_equally():
    v, n, err2 = _quadratic_game(np.random.default_rng(1))
    phi = shapley(err2, 3, err2(()), err2((0, 1, 2)))
    total = v.sum(axis=0)
    for k in range(3):                       # phi_k = v_k . (sum_j v_j) + v_k . 2n... per point, exactly
        assert phi[:, k] == pytest.approx(np.sum(v[k] * (total + 2 * n), axis=1), rel=1e-9, abs=1e-12)
    assert phi.sum(axis=1) == pytest.approx(err2(()) - err2((0, 1, 2)))
    table = {S: np.random.default_rng(len(S)).exponential(size=5) + sum(S) for S in    # any game: efficient
             [(), (0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]}
    phi = shapley(lambda S: table[S], 3, table[()], table[(0, 1, 2)])
    assert phi.sum(axis=1) == pytest.approx(table[()] - table[(0, 1, 2)])


@pytest.mark.unit
def test_sampled_orders_keep_the_sum_and_the_order_independence(monkeypatch):
    import robocal.diagnose.budget as budget

    v, n, err2 = _quadratic_game(np.random.default_rng(2), K=4)
    exact = shapley(err2, 4, err2(()), err2((0, 1, 2, 3))).mean(axis=0)
    monkeypatch.setattr(budget, "EXACT_MAX", 2)
    sampled = shapley(err2, 4, err2(()), err2((0, 1, 2, 3))).mean(axis=0)
    assert sampled.sum() == pytest.approx(exact.sum())
    assert sampled == pytest.approx(exact, abs=0.25 * np.abs(exact).max())


def _terms(rng, M=120, layer_worse=False):
    q = rng.uniform(-2, 2, (M, 6))
    floor2 = np.full(M, 0.03**2)
    final = floor2 + rng.exponential(0.02**2, M)
    layer = final * (1.05 if layer_worse else 0.8)
    kin = final + rng.exponential(0.1**2, M)
    nominal = kin + rng.exponential(1.0, M)
    phi = np.stack([0.7 * (kin - final), 0.3 * (kin - final)], axis=1)
    return BudgetTerms(nominal, kin, phi, ("a", "b"), final, layer, "joint GP", floor2, 0.5, q, "test")


@pytest.mark.unit
def test_budget_closes_and_what_does_not_close_is_what_was_clipped():
    rng = np.random.default_rng(3)
    t = _terms(rng)
    names, D = per_point(t)
    assert D.sum(axis=1) == pytest.approx(t.nominal)              # every point's row telescopes
    b = error_budget(t, boot=200)
    assert [c.kind for c in b.components] == ["geometry", "effect", "effect", "layer", "floor", "structure", "noise"]
    assert b.closure < 1e-12 and b.nominal_rms_mm == pytest.approx(math.sqrt(np.mean(t.nominal)))
    for c in b.components:
        assert c.low_mm <= c.rms_mm + 1e-12 and c.rms_mm <= c.high_mm + 1e-12
    tw = _terms(np.random.default_rng(3), layer_worse=True)
    worse = error_budget(tw, boot=50)
    assert worse.component("residual layer (joint GP)").rms_mm == 0.0 and worse.closure > 0
    assert worse.sum_rms_mm**2 - worse.nominal_rms_mm**2 == pytest.approx(np.mean(tw.layer - tw.final))
    assert ErrorBudget.from_dict(b.to_dict()) == b


@pytest.mark.unit
def test_noise_shape_tells_joint_jitter_from_the_declared_noise():
    rng = np.random.default_rng(4)
    N = 600
    J = rng.normal(0, 800.0, (N, 3, 3))                           # mm/rad, three joints
    cov = np.broadcast_to(np.diag([1e-4, 4e-4, 4e-4]), (N, 3, 3)).copy()
    s = np.radians([0.004, 0.004, 0.0])
    r = np.einsum("nij,nj->ni", J, rng.normal(size=(N, 3)) * s) + rng.multivariate_normal(np.zeros(3), cov[0], N)
    shape = noise_shape(r, cov, J)
    assert np.degrees(shape["joint_sigma_rad"][:2]) == pytest.approx([0.004, 0.004], rel=0.15)
    assert np.degrees(shape["joint_sigma_rad"][2]) < 0.001 and 0.6 < shape["declared_scale"] < 1.4
    white = nugget(rng.normal(0, 0.05, (N, 3)), rng.uniform(-1, 1, (N, 4)))
    assert white["nugget_mm2"] == pytest.approx(3 * 0.05**2, rel=0.2)
    x = rng.uniform(-1, 1, (N, 4))
    smooth = nugget(0.1 * np.stack([np.sin(2 * x[:, 0]), np.cos(2 * x[:, 1]), x[:, 2]], axis=1), x)
    assert smooth["nugget_mm2"] < 0.3 * smooth["sill_mm2"]
    rem = Remainder("noise", 0.1, 0.11, 0.03, "noisy joint readings", "text", {"nugget_mm": 0.1})
    assert Remainder.from_dict(rem.to_dict()) == rem


@pytest.mark.system
def test_joint_jitter_above_the_floor_is_noise_and_a_non_physical_fit_is_unexplained():
    """Jitter of 0.004 deg on J1-J3, no effect: nothing accepted, the remainder is noise of the joint readings
    (not structure), the budget says so. A reach-dependent J2 sag outside the library: the best description has
    a negative stiffness on the lever form's path (the selection's first), so the verdict is unexplained and names
    it; on the links' path, which the selection keeps here, the verdict names the missing reach term."""
    d = diagnose(truth_input(simulate(["joint_jitter"], 5001, SMALL, 1.0)))
    assert not d.accepted_effects and not d.unexplained and d.remainder.kind == "noise"
    assert d.remainder.source.startswith("noisy joint readings")
    b = d.budget
    assert b.component("excess noise").rms_mm > 3 * b.component("unexplained structure").rms_mm
    report = d.to_dict()
    assert {"name", "rms_mm", "low_mm", "high_mm"} <= set(report["budget"]["components"][0])
    assert report["remainder"]["kind"] == "noise" and report["budget"]["closure"] < 0.05
    assert report["next_steps"][0]["experiment"].startswith("log the commanded joints")
    sag = truth_input(simulate(["reach_sag_j2"], 5001, TruthProtocol(timestamps=False)))
    with mock.patch.object(select, "LINKS_PATH_GAIN", None):        # the lever form's path alone
        d = diagnose(sag)
    bad = d.unexplained_structure.get("nonphysical")
    assert d.unexplained and d.to_dict()["unexplained"] and bad
    assert any("negative" in w for b in bad for w in b["why"]) and d.unexplained_structure["best_description"]
    assert any(f.evidence.get("unexplained") for f in d.findings if f.accepted)
    d = diagnose(sag)          # the links' path, kept: physical values, and the term the model lacks is named
    assert d.unexplained and not d.unexplained_structure.get("nonphysical")
    assert "vertical sag growing with the reach" in d.unexplained_structure["text"]
