"""The one effect engine (robocal.effects): blocked cross-validation, candidates and what cannot be told, forward
selection on independent truth campaigns (robocal/simulation/truth_cell.py), the joint fit, the physical reading, the model."""
import json
from dataclasses import replace

import numpy as np
import pytest

from robocal.kinematics.gravity import GravityModel
from robocal.effects.bases import apply_effects, effect_regressor, gear_cyclic, joint_compliance
from robocal.effects.cv import RIDGE, BlockedCV, Blocking, order_blocks, pose_blocks, spread_scaled, varies
from robocal.effects.model import EffectChoice, FittedEffect
from robocal.effects.fit import calibrate_elastic
from robocal.effects.library import candidates
from robocal.effects.physical import reading
from robocal.effects.engine import run_engine
from robocal.effects.engine import select_candidates
from robocal.effects.library import LibraryOptions, scan_families, scan_orders
import robocal.effects.select as select
from robocal.measure.stats import paired_gain, signed_rank_z
from robocal.identify.identification import CalibrationOptions, calibrate
from robocal.kinematics.models import ParamLayout, smr_tracker
from robocal.layers.calibrated_model import CalibratedModel
from robocal.diagnose.selfcheck import truth_input
from robocal.simulation.truth_cell import TruthProtocol, simulate
from tests.cells import T_SEED000, irb2600

SMALL = TruthProtocol(n_calib=200, n_test=60, check_poses=6, check_repeats=4)


def engine_on(camp, **kw):
    """Geometric LM fit of the calib rows of a truth campaign, then the engine on them."""
    inp = truth_input(camp)
    cal = np.flatnonzero(inp.calib)
    geo = calibrate(inp.kin, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], CalibrationOptions(method="lm"))
    cols = np.array([ParamLayout.of(inp.kin).index(n) for n in geo.identified])
    meta = {k: (None if v is None else np.asarray(v)[cal]) for k, v in inp.meta().items()}
    return inp, geo, cols, meta, run_engine(geo.kinematics, cols, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal],
                                            meta, **kw)


def rms(e):
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def ridge_fit(A_rows: np.ndarray, y_rows: np.ndarray, norms: np.ndarray) -> np.ndarray:
    """Parameters x of A_rows (n, P) ~ y_rows (n,) with the cross-validation's ridge on the columns scaled to the
    norms (P,) they have over all rows (in the units of A)."""
    As = A_rows / norms
    x = np.linalg.solve(As.T @ As + RIDGE * np.eye(len(norms)), As.T @ y_rows)
    return x / norms


@pytest.mark.unit
def test_blocked_cv_equals_a_brute_force_refit_per_fold():
    rng = np.random.default_rng(0)
    N, P = 120, 5
    A = rng.normal(size=(N, 3, P))
    y = A @ rng.normal(size=P) + rng.normal(0, 0.1, (N, 3))
    W = np.broadcast_to(np.diag([1.0, 2.0, 0.5]), (N, 3, 3)).copy()
    fold = pose_blocks(rng.normal(size=(N, 6)), 4, seed=1)
    cv = BlockedCV(A, y, W, [Blocking("pose", fold)])
    cols = np.array([0, 2, 4])
    se = cv.squared_errors(cols)["pose"]
    ref = np.empty(N)
    norms = np.linalg.norm(np.einsum("nij,njk->nik", W, A[:, :, cols]).reshape(-1, 3), axis=0)
    for f in np.unique(fold):
        tr, te = fold != f, fold == f
        Aw = np.einsum("nij,njk->nik", W[tr], A[tr][:, :, cols]).reshape(-1, 3)
        x = ridge_fit(Aw, np.einsum("nij,nj->ni", W[tr], y[tr]).reshape(-1), norms)
        ref[te] = np.sum((y[te] - A[te][:, :, cols] @ x) ** 2, axis=1)
    np.testing.assert_allclose(se, ref, rtol=1e-6)


@pytest.mark.unit
def test_cv_gives_no_weight_to_a_column_the_fit_would_fix_at_zero(monkeypatch):
    """A column whose relative residual against the others is below the fit's rank_tol over all rows (so
    ``calibrate_elastic`` fixes it at zero), and far smaller on every fold's training rows than on the rows that fold
    holds out, leaves the held-out errors as they are. With the ridge at 1e-9 it took a large weight in the training
    folds and inflated them (the few-rows case: 40 rows, five folds)."""
    assert RIDGE == pytest.approx(CalibrationOptions().rank_tol ** 2)
    rng = np.random.default_rng(10)
    N = 40
    fold = np.arange(N) % 5
    A = rng.normal(size=(N, 3, 5))
    A[:, :, 4] = A[:, :, 0] + np.where(fold == 0, 1.5e-3, 1e-4)[:, None] * rng.normal(size=(N, 3))
    y = A[:, :, :4] @ rng.normal(size=4) + rng.normal(0, 0.1, (N, 3))
    flat = A.reshape(-1, 5)
    Q = np.linalg.qr(flat[:, :4])[0]
    rest = flat[:, 4] - Q @ (Q.T @ flat[:, 4])
    assert np.linalg.norm(rest) / np.linalg.norm(flat[:, 4]) < CalibrationOptions().rank_tol

    def ratio() -> float:
        cv = BlockedCV(A, y, np.broadcast_to(np.eye(3), (N, 3, 3)).copy(), [Blocking("pose", fold)])
        return rms(cv.errors(np.arange(5))) / rms(cv.errors(np.arange(4)))
    assert ratio() == pytest.approx(1.0, abs=0.01)
    monkeypatch.setattr("robocal.effects.cv.RIDGE", 1e-9)
    assert ratio() > 1.2


def _scan_problem(seed: int, signal: float = 0.0, N: int = 90, K: int = 12):
    """A base design (N, 3, 4) and K two-column alternatives; y = noise (+ ``signal`` x alternative 5)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, 3, 4 + 2 * K))
    y = rng.normal(0, 1.0, (N, 3)) + signal * A[:, :, 4 + 10:4 + 12] @ np.array([1.0, -0.5])
    alts = [np.array([4 + 2 * k, 5 + 2 * k]) for k in range(K)]
    fold = np.arange(N) % 5
    cv = BlockedCV(A, y, np.broadcast_to(np.eye(3), (N, 3, 3)).copy(), [Blocking("pose", fold)])
    return A, y, alts, fold, cv


@pytest.mark.unit
def test_a_scan_is_cross_validated_with_its_pick_inside_every_fold():
    """``scan_errors`` equals a brute-force refit per fold that picks the alternative on the training rows alone;
    ``scan_pick`` is the alternative that fits all rows best."""
    A, y, alts, fold, cv = _scan_problem(3)                # noise: the folds pick different alternatives
    base = np.arange(4)
    ref = np.empty(len(y))

    def fit(rows, cols):
        x = ridge_fit(A[rows][:, :, cols].reshape(-1, len(cols)), y[rows].reshape(-1),
                      np.linalg.norm(A[:, :, cols].reshape(-1, len(cols)), axis=0))
        return x, float(np.sum((y[rows] - A[rows][:, :, cols] @ x) ** 2))
    for f in range(5):
        tr, te = fold != f, fold == f
        best = min(alts, key=lambda a: fit(tr, np.concatenate([base, a]))[1])
        cols = np.concatenate([base, best])
        ref[te] = np.sum((y[te] - A[te][:, :, cols] @ fit(tr, cols)[0]) ** 2, axis=1)
    np.testing.assert_allclose(np.sum(cv.scan_errors(base, alts) ** 2, axis=1), ref, rtol=1e-6)
    picks = {min(range(len(alts)), key=lambda k: fit(fold != f, np.concatenate([base, alts[k]]))[1]) for f in range(5)}
    assert len(picks) > 1                                 # (so the test sees a pick made on all rows)
    assert _scan_problem(3, signal=0.4)[4].scan_pick(base, alts) == 5


@pytest.mark.unit
def test_a_nested_scan_is_not_optimistic_on_noise_where_picking_on_all_rows_is():
    """Pure noise, 40 seeds: the order picked on all rows and then cross-validated looks better than the base
    (selection bias); nested, the same scan does not."""
    nested, picked = [], []
    for seed in range(40):
        A, y, alts, fold, cv = _scan_problem(100 + seed)
        base = np.arange(4)
        e0 = np.mean(cv.squared_errors(base)["pose"])
        nested.append(np.mean(np.sum(cv.scan_errors(base, alts) ** 2, axis=1)) / e0)
        best = alts[cv.scan_pick(base, alts)]
        picked.append(np.mean(cv.squared_errors(np.concatenate([base, best]))["pose"]) / e0)
    assert np.mean(picked) < 1.0 < np.mean(nested)


@pytest.mark.unit
def test_the_scan_offers_orders_with_two_periods_over_the_span_and_four_values_per_period():
    assert scan_orders(81.0, 1000) == tuple(range(9, 41))      # 2 periods over 81 deg from the 9th; 40 at most
    assert scan_orders(360.0, 1000) == tuple(range(5, 41))     # above the low harmonics 1-4 of a full turn
    assert scan_orders(300.0, 39) == tuple(range(5, 12))       # 39 values over 300 deg: 4 per period up to the 11th
    assert scan_orders(300.0, 10) == ()
    q = np.radians(np.column_stack([np.linspace(-40, 41, 100), np.full(100, 10.0)]))
    families, cannot = scan_families(q)
    assert [dict(f[0].options)["joint"] for f in families] == [1] and len(families[0]) == 32
    assert scan_families(q, LibraryOptions(scan_max_rows=99)) == ([], [{
        "effect": "gear_cyclic", "joints": [1, 2], "reason": "cyclic errors of a higher order are scanned up to 99 rows"}])


@pytest.mark.unit
def test_pose_blocks_hold_neighbours_out_together_and_order_blocks_are_contiguous():
    rng = np.random.default_rng(1)
    q = np.concatenate([rng.normal(c, 0.01, (30, 6)) for c in rng.uniform(-2, 2, (8, 6))])
    fold = pose_blocks(q, 4, seed=0, block_points=30)
    for c in range(8):                                    # each tight cluster lands in one fold
        assert len(set(fold[c * 30:(c + 1) * 30])) == 1
    assert len(set(fold)) == 4
    ob = order_blocks(np.arange(200.0), 5)
    assert np.all(ob[:10] == ob[0]) and len(np.flatnonzero(np.diff(ob))) == 19


@pytest.mark.unit
def test_a_joint_held_at_one_angle_does_not_collapse_the_pose_blocks():
    """A grid that holds J6 at one angle, its values differing in the last bits (a spread of ~1e-15 rad): the pose
    blocks still spread the poses over every fold, as without J6 (dividing by that spread once made J6 the largest
    coordinate, and k-means put every pose in one cluster: one fold, no cross-validation)."""
    rng = np.random.default_rng(2)
    q = rng.uniform(-1.5, 1.5, (400, 6))
    q[:, 5] = -np.pi / 2 + rng.integers(-2, 3, 400) * np.spacing(np.pi / 2)
    assert 0 < q[:, 5].std() < 1e-14
    fold = pose_blocks(q, 5, seed=0)
    np.testing.assert_array_equal(fold, pose_blocks(q[:, :5], 5, seed=0))
    assert np.bincount(fold).min() > 40
    x = spread_scaled(q)
    assert x.shape == (400, 5) and np.allclose(x.mean(axis=0), 0) and np.allclose(x.std(axis=0), 1)
    assert varies(q).tolist() == [True] * 5 + [False]


@pytest.mark.unit
def test_what_the_data_cannot_tell_is_named_with_the_reason():
    kin = irb2600()
    q = np.random.default_rng(2).uniform(-1, 1, (80, 6))
    q[:, 3] = 0.2                                           # J4 fixed: no gear error can show on it
    meta = {"payload_kg": np.zeros(80), "approach": None, "move": None, "order": None, "t_s": None}
    cands, cannot = candidates(kin, q, meta, GravityModel())
    why = {(u["effect"], tuple(u["joints"])): u["reason"] for u in cannot}
    assert "no measurement order" in why[("readback_lag", (1, 2, 3, 4, 5, 6))]
    assert "no measurement order" in why[("backlash", (1, 2, 3, 4, 5, 6))]
    assert "no timestamps and no measurement order" in why[("registration_drift", ())]
    assert "covers only" in why[("gear_cyclic", (4,))] and "payload" in why[("payload_deflection", (2, 3))]
    assert "J4 and J5" in why[("axis_coupling", (4, 5, 6))]
    assert {c.name for c in cands} == {"joint_compliance", "gear_cyclic"}


@pytest.mark.unit
def test_no_drift_is_offered_in_a_clock_that_follows_the_place():
    """Poses measured along a serpentine grid without timestamps: the order is a shape in space, so neither drift
    is offered and the reason says so; the same poses in random order (or the check off) offer the drift."""
    kin = irb2600()
    g = np.linspace(-0.6, 0.6, 8)
    rows = [(a, b, c) for i, a in enumerate(g) for j, b in enumerate(g[::(-1) ** i])
            for c in (g if (i * 8 + j) % 2 == 0 else g[::-1])]         # serpentine over J1, J2, J3
    q = np.zeros((len(rows), 6))
    q[:, :3] = rows
    q[:, 1] += 0.3
    q[:, 4] = 0.8
    meta = {"payload_kg": np.zeros(len(q)), "approach": None, "move": None, "order": np.arange(len(q), dtype=float),
            "t_s": None}
    cands, cannot = candidates(kin, q, meta, GravityModel())
    why = {u["effect"]: u["reason"] for u in cannot}
    assert "registration_drift" not in {c.name for c in cands}
    assert "measurement order follows the place" in why["registration_drift"]
    shuffled = {**meta, "order": np.random.default_rng(4).permutation(len(q)).astype(float)}
    assert "registration_drift" in {c.name for c in candidates(kin, q, shuffled, GravityModel())[0]}
    off = LibraryOptions(clock_place_max_r2=None)
    assert "registration_drift" in {c.name for c in candidates(kin, q, meta, GravityModel(), off)[0]}
    timed = {**meta, "t_s": 30.0 * np.arange(len(q))}                 # timestamps along the same path
    cands, cannot = candidates(kin, q, timed, GravityModel())
    assert not {"registration_drift", "thermal_drift"} & {c.name for c in cands}
    assert sum("time follows the place" in u["reason"] for u in cannot) == 2


@pytest.mark.unit
def test_signed_rank_z_is_wilcoxons_normal_approximation():
    """Against scipy's one-sided signed-rank test (normal approximation, zeros dropped, ties' variance corrected)."""
    from scipy.stats import norm, wilcoxon
    rng = np.random.default_rng(5)
    base = np.round(rng.exponential(1.0, 150), 2)
    cand = np.round(base * rng.uniform(0.6, 1.3, 150), 2)
    cand[:10] = base[:10]                                            # zeros, and ties from the rounding
    ref = wilcoxon(base - cand, alternative="greater", method="approx", correction=False, zero_method="wilcox")
    assert signed_rank_z(base, cand) == pytest.approx(norm.isf(ref.pvalue), rel=1e-9)
    assert signed_rank_z(cand, base) == pytest.approx(-signed_rank_z(base, cand))


@pytest.mark.unit
def test_a_gain_over_most_points_that_a_few_large_differences_hide_from_the_t_is_taken_by_the_ranks():
    """80 of 100 points gain a little, and 6 far points differ by much, either way: the gain is large (> 10 %), the
    paired t is below 2 and the signed ranks clear z > 2, so the rank rule takes it, and only it; a small gain
    with clear ranks is not taken."""
    rng = np.random.default_rng(3)
    base = np.full(100, 1.0)
    base[:6] = 40.0
    cand = base - np.where(np.arange(100) < 86, 0.8, -0.2)
    cand[:6] = base[:6] + np.array([-30.0, -25.0, 24.0, 26.0, -20.0, -5.0]) + rng.normal(0, 0.1, 6)
    g = paired_gain(base, cand)
    assert g.gain > select.LARGE_GAIN and g.t < select.LARGE_T and signed_rank_z(base, cand) > 2
    assert select._supported(g, base, cand)
    assert select._needed(g, base, cand, select.KEEP_GAIN)
    made = select.RANK_Z
    try:
        select.RANK_Z = None
        assert not select._supported(g, base, cand) and not select._needed(g, base, cand, select.KEEP_GAIN)
    finally:
        select.RANK_Z = made
    small = base - np.where(np.arange(100) < 86, 0.05, -0.02)
    small[:6] = base[:6]
    g = paired_gain(base, small)
    assert g.gain < select.TAKE_GAIN and signed_rank_z(base, small) > 2
    assert not select._supported(g, base, small)


@pytest.mark.system
def test_compliance_of_the_truth_module_is_taken_and_predicts_the_test_rows():
    camp = simulate(["joint_compliance"], 11, SMALL)
    inp, geo, cols, meta, eng = engine_on(camp)
    assert [c.name for c in eng.taken] == ["joint_compliance"]
    test = np.flatnonzero(inp.test)
    model = CalibratedModel(eng.elastic.kinematics, None, None, eng.elastic.effects)
    tmeta = {k: (None if v is None else np.asarray(v)[test]) for k, v in inp.meta().items()}
    e_geo = rms(inp.p_mm[test] - smr_tracker(geo.kinematics, inp.q_rad[test]))
    e_el = rms(inp.p_mm[test] - model.smr_tracker(inp.q_rad[test], tmeta))
    assert e_el < 1.3 * inp.noise_floor_mm < 0.5 * e_geo
    again = CalibratedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    np.testing.assert_allclose(again.smr_tracker(inp.q_rad[test], tmeta), model.smr_tracker(inp.q_rad[test], tmeta),
                               atol=1e-9)


@pytest.mark.system
def test_nothing_is_taken_on_geometric_only_data():
    for seed in (21, 22, 23):
        _, _, _, _, eng = engine_on(simulate([], seed, SMALL))
        assert eng.taken == () and eng.elastic is None
        assert len({t.label for t in eng.selection.trials}) >= 10


@pytest.mark.system
def test_a_cyclic_error_of_a_high_order_is_found_at_its_order_and_predicts_the_test_rows():
    """A J1 cyclic error of 14 periods per revolution (20 arcsec) on a geometric truth campaign: the scan takes
    ``gear_cyclic(J1 h14)``, and the model predicts the test rows better than the geometry."""
    camp = simulate([], 31, SMALL)
    amp = np.radians(20.0 / 3600.0) * np.array([0.8, -0.6])
    eff = gear_cyclic(1, (14,))
    dp = effect_regressor(camp.truth_kin, camp.q_cmd_rad, {}, eff) @ amp
    inp, geo, cols, meta, eng = engine_on(replace(camp, p_mm=camp.p_mm + dp))
    assert "gear_cyclic(J1 h14)" in [c.label for c in eng.taken]
    fe = next(f for f in eng.elastic.effects if f.choice.label == "gear_cyclic(J1 h14)")
    np.testing.assert_allclose(fe.values, amp, atol=0.25 * np.abs(amp).max())
    test = np.flatnonzero(inp.test)
    tmeta = {k: (None if v is None else np.asarray(v)[test]) for k, v in inp.meta().items()}
    model = CalibratedModel(eng.elastic.kinematics, None, None, eng.elastic.effects)
    e_geo = rms(inp.p_mm[test] - smr_tracker(geo.kinematics, inp.q_rad[test]))
    assert rms(inp.p_mm[test] - model.smr_tracker(inp.q_rad[test], tmeta)) < 0.8 * e_geo


@pytest.mark.system
def test_readback_lag_is_taken_for_a_lag_and_backlash_for_backlash():
    for truth, other in (("readback_lag", "backlash"), ("backlash", "readback_lag")):
        camp = simulate([truth], 31, TruthProtocol(**{**SMALL.__dict__, "timestamps": False}))
        *_, eng = engine_on(camp)
        names = [c.name for c in eng.taken]
        assert truth in names and other not in names, names
    lag = camp.truths[0] if truth == "readback_lag" else None
    assert lag is None or lag.name == "readback_lag"


@pytest.mark.system
def test_a_drift_in_measurement_order_is_taken_without_timestamps_and_is_zero_for_a_commanded_target():
    camp = simulate(["registration_drift"], 41, TruthProtocol(**{**SMALL.__dict__, "timestamps": False}), scale=2.0)
    inp, _, _, meta, eng = engine_on(camp)
    drift = [fe for fe in eng.elastic.effects if fe.choice.name == "registration_drift"]
    assert drift and dict(drift[0].choice.options)["clock"] == "order"
    model = CalibratedModel(eng.elastic.kinematics, None, None, eng.elastic.effects)
    q = inp.q_rad[:5]
    late = {"order": np.full(5, float(np.max(meta["order"])))}
    assert np.max(np.abs(model.smr_tracker(q, late) - model.smr_tracker(q, {}))) > 0.02
    np.testing.assert_allclose(model.smr_tracker(q, {}), model.smr_tracker(q, {"order": np.zeros(5)}), atol=1e-12)


@pytest.mark.system
def test_gravity_direction_of_a_wall_mount_is_used():
    """A wall-mounted robot (gravity along +x of its base): with the config's direction the compliance fit (mass
    distribution free) reaches the floor; with the floor direction it does not."""
    wall = (1.0, 0.0, 0.0)
    camp = simulate(["joint_compliance"], 51, TruthProtocol(**{**SMALL.__dict__, "gravity_base": wall}))
    inp, geo, cols, meta, _ = engine_on(camp)
    cal = np.flatnonzero(inp.calib)
    out = {}
    for name, g in (("wall", GravityModel(gravity_base=wall)), ("floor", GravityModel())):
        choice = EffectChoice("joint_compliance", (("joints", (1, 2, 3)), ("form", "levers"),
                                                   ("gravity_base", g.gravity_base)))
        el = calibrate_elastic(geo.kinematics, cols, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], meta, [choice])
        out[name] = rms(el.residual_tracker_mm)
    assert out["wall"] < 1.3 * inp.noise_floor_mm < out["floor"]


@pytest.mark.unit
def test_lever_form_typical_values_deflect_as_much_as_the_gravity_form():
    """The lever and the link forms' typical values (its prior in the adaptive design and the predicted curve) describe the
    same physical effect as the gravity form's: at typical values both deflect J2 and J3 by the same order (the
    old 3e-8 rad kg/(N m) per point gave 1/70 of it)."""
    kin = irb2600().with_(T_tracker_base=T_SEED000)
    q = np.random.default_rng(3).uniform(-1.2, 1.2, (400, 6))
    meta = {"payload_kg": np.full(400, 3.0)}
    dq = {}
    for form in ("gravity", "levers", "links"):
        eff = joint_compliance(form=form)
        assert len(eff.typical) == len(eff.param_names) == eff.basis(kin, q, meta).dq.shape[2]
        dq[form] = np.sqrt(np.mean((eff.basis(kin, q, meta).dq @ np.asarray(eff.typical))[:, 1:3] ** 2, axis=0))
    for form in ("levers", "links"):
        ratio = dq[form] / dq["gravity"]
        assert np.all((ratio > 0.5) & (ratio < 5.0)), (form, ratio)


@pytest.mark.unit
def test_gravity_model_from_config_masses_mass_class_or_default():
    g = GravityModel.of_robot(6, link_masses_kg=(0, 10, 8, 2, 1, 0.5))
    assert g.source == "config" and g.link_masses_kg[1] == 10
    g = GravityModel.of_robot(6, mass_kg=100.0, gravity_base=(0, 0, -2))
    assert g.source == "mass class" and sum(g.link_masses_kg) == pytest.approx(70.0)
    assert g.gravity_base == (0.0, 0.0, -1.0)
    assert GravityModel.of_robot(6).source == "default"


@pytest.mark.unit
def test_physical_reading_flags_values_outside_their_range_without_dropping_them():
    kin = irb2600().with_(T_tracker_base=T_SEED000)
    q = np.random.default_rng(5).uniform(-1, 1, (50, 6))
    meta = {"payload_kg": np.zeros(50)}
    comp = FittedEffect(EffectChoice("joint_compliance", (("joints", (2, 3)),)), np.array([-2e-6, 5e-7]),
                        np.full(2, np.nan), ("c2", "c3"), "rad/(N*m)")
    r = reading(comp, kin, q, meta, GravityModel())
    assert not r["plausible"] and "negative" in r["outside"][0] and "gravity direction" in r["check"]
    assert r["quantities"]["J3"]["stiffness_nm_per_rad"] == pytest.approx(2e6, rel=1e-6)
    gear = FittedEffect(EffectChoice("gear_cyclic", (("joint", 1), ("harmonics", (1,)))), np.array([2e-3, 0.0]),
                        np.full(2, np.nan), ("sin1", "cos1"), "rad")
    r = reading(gear, kin, q, meta, GravityModel())
    assert not r["plausible"] and r["quantities"]["amplitude_arcsec"]["h1"] == pytest.approx(412.5, rel=1e-3)


@pytest.mark.unit
def test_identifiability_reports_an_effect_parameter_the_poses_cannot_separate():
    """J1 gear harmonic with J1 fixed: its columns are constant, redundant with the base registration."""
    rng = np.random.default_rng(5)
    nominal = irb2600()
    truth = nominal.with_(T_tracker_base=T_SEED000)
    q = rng.uniform(-1, 1, (120, 6))
    q[:, 0] = 0.3
    meta = {"payload_kg": np.full(120, 10.0)}
    p = apply_effects(truth, q, meta, [(joint_compliance((2, 3)), np.array([1e-6, 2e-6]))])
    geo = calibrate(nominal, q, p, None, CalibrationOptions(method="lm"))
    cols = np.array([ParamLayout.of(nominal).index(n) for n in geo.identified])
    el = calibrate_elastic(geo.kinematics, cols, q, p, None, meta,
                           [EffectChoice("joint_compliance", (("joints", (2, 3)),)),
                            EffectChoice("gear_cyclic", (("joint", 1),))])
    names = {u.name for u in el.unidentifiable}
    assert {"gear_cyclic(J1).sin1", "gear_cyclic(J1).cos1"} & names
    assert el.effects[0].values[0] == pytest.approx(1e-6, rel=0.05)


@pytest.mark.system
def test_select_is_deterministic():
    camp = simulate(["backlash"], 61, TruthProtocol(n_calib=120, n_test=20, check_poses=4, check_repeats=3))
    inp, geo, cols, meta, eng = engine_on(camp)
    cal = np.flatnonzero(inp.calib)
    again = select_candidates(geo.kinematics, cols, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], meta)
    assert again.selection.to_dict() == eng.selection.to_dict()


@pytest.mark.system
def test_the_scan_takes_nothing_on_sparse_geometric_only_campaigns():
    """20 geometric-only truth campaigns of 40-100 calibration poses (pure noise beyond the geometry): no cyclic
    error of a higher order is taken, where the scan tries about 30 orders per joint on each."""
    tried = 0
    for seed in range(20):
        n = 40 + 3 * seed
        _, _, _, _, eng = engine_on(simulate([], 300 + seed, TruthProtocol(n_calib=n, n_test=20, check_poses=3,
                                                                          check_repeats=2)))
        high = [c.label for c in eng.taken if c.name == "gear_cyclic" and min(dict(c.options)["harmonics"]) > 4]
        assert high == [], f"seed {300 + seed}, {n} poses: {high}"
        tried += sum(1 for lb in eng.selection.candidates if "-" in lb)
    assert tried >= 40                                   # the scan ran (families on most joints)


@pytest.mark.system
def test_beyond_max_rows_the_choices_are_those_of_a_seeded_subset_and_say_so():
    """The selection and the residual-layer choice on more rows than ``max_rows``: exactly their answer on a seeded
    subset of ``max_rows`` rows (the rows kept in order), reported as such; the taken effects fitted on all rows."""
    from robocal.effects.bases import meta_rows
    from robocal.effects.cv import capped_rows
    from robocal.effects.engine import EngineOptions
    from robocal.layers.choice import choose_layer
    assert capped_rows(100, 100) is None
    sub = capped_rows(200, 120, seed=3)
    assert len(sub) == 120 and np.all(np.diff(sub) > 0) and np.array_equal(sub, capped_rows(200, 120, seed=3))
    camp = simulate(["joint_compliance"], 11, SMALL)
    inp = truth_input(camp)
    cal = np.flatnonzero(inp.calib)
    geo = calibrate(inp.kin, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], CalibrationOptions(method="lm"))
    cols = np.array([ParamLayout.of(inp.kin).index(n) for n in geo.identified])
    meta = {k: (None if v is None else np.asarray(v)[cal]) for k, v in inp.meta().items()}
    q, p, cov = inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal]
    rows = capped_rows(len(cal), 150)
    lib = LibraryOptions(scan_max_rows=100)            # no scan (its orders depend on the rows' distinct angles)
    capped = run_engine(geo.kinematics, cols, q, p, cov, meta, options=EngineOptions(max_rows=150, library=lib))
    direct = select_candidates(geo.kinematics, cols, q[rows], p[rows], cov[rows], meta_rows(meta, rows),  # meta_rows:
                               options=EngineOptions(library=lib))                             # the warm-up's reference
    assert capped.selection.rows == (150, len(cal)) and direct.selection.rows == (150, 150)
    assert [t.label for t in capped.selection.trials] == [t.label for t in direct.selection.trials]
    assert [t.cv_rms_mm for t in capped.selection.trials] == pytest.approx(      # (a drift's clock span: all rows';
        [t.cv_rms_mm for t in direct.selection.trials], rel=1e-6)                 # the CV keeps float32)
    assert [c.label for c in capped.taken] == [c.label for c in direct.taken]
    d = capped.selection.to_dict()
    assert (d["rows"], d["of_rows"]) == (150, len(cal)) and "seeded subset of 150" in d["method"]
    assert "rows" not in direct.selection.to_dict()
    assert len(capped.elastic.residual_tracker_mm) == len(cal)                 # fitted on every row
    model = CalibratedModel(capped.elastic.kinematics, None, None, capped.elastic.effects)
    lay = choose_layer(model, q, p, meta, max_rows=100)
    few = capped_rows(len(cal), 100)
    same = choose_layer(model, q[few], p[few], meta_rows(meta, few))
    assert lay.rows == (100, len(cal)) and lay.cv == same.cv and lay.to_dict()["of_rows"] == len(cal)


@pytest.mark.unit
def test_a_model_with_the_link_form_round_trips_through_json():
    """A model whose compliance has the link form (taken by config) predicts the same after model.json."""
    kin = irb2600().with_(T_tracker_base=T_SEED000)
    choice = EffectChoice("joint_compliance", (("joints", (2, 3)), ("form", "links")))
    eff = choice.build(kin.n)
    values = np.asarray(eff.typical) * np.random.default_rng(8).uniform(-2.0, 2.0, eff.k)
    model = CalibratedModel(kin, None, None, (FittedEffect(choice, values, np.full(eff.k, np.nan), eff.param_names,
                                                           eff.unit),))
    back = CalibratedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    q = np.random.default_rng(9).uniform(-1.0, 1.0, (50, 6))
    meta = {"payload_kg": np.full(50, 5.0)}
    assert np.max(np.abs(model.smr_tracker(q, meta) - smr_tracker(kin, q))) > 0.01
    np.testing.assert_allclose(back.smr_tracker(q, meta), model.smr_tracker(q, meta), atol=1e-9)
