"""Diagnosis on campaigns from the independent truth generator (robocal/simulation/truth_cell.py, written from the physics, not from
the engine): the failure classes of real campaigns (compliance + misalignment + gear on a small arm, compliance
sampled sparsely at the extremes, a drift that follows J1 through the measurement order, a read-back lag with
compliance), read-back lag vs backlash, and a reduced self-check (the full one: bench/bench_diagnose.py)."""
from pathlib import Path

import numpy as np
import pytest

from robocal.diagnose.core import diagnose
from robocal.diagnose.selfcheck import FORMS, run_self_check, run_trial, truth_input
from robocal.simulation.truth_cell import TruthProtocol, gravity_torque_nm, random_mass_model, simulate
from tests.test_structure import ROOT, import_edges, modules

ENGINE = ("robocal.diagnose", "robocal.effects", "robocal.effects")   # what the truth must never load

SMALL = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4, timestamps=False)


def accepted(d):
    return {f.effect: f for f in d.findings if f.accepted}


def import_closure(root: Path, start: str) -> set[str]:
    """Project modules that importing ``start`` may run: every import statement (functions included) followed,
    and the ``__init__`` of every package on the way (Python runs it before the module)."""
    mods = modules(root)
    todo, seen = [start], set()
    while todo:
        name = todo.pop()
        if name in seen or name not in mods:
            continue
        seen.add(name)
        parts = name.split(".")
        todo += [".".join(parts[:k]) for k in range(1, len(parts))]
        todo += [e.target for e in import_edges(name, mods[name], mods)]
    return seen


@pytest.mark.unit
def test_truth_generator_is_independent_of_the_engine():
    closure = import_closure(ROOT, "robocal.simulation.truth_cell")
    assert "robocal.kinematics" in closure and not [m for m in closure if m.startswith(ENGINE)], sorted(closure)


@pytest.mark.unit
def test_the_independence_check_sees_the_engine_through_a_package_init(tmp_path):
    files = {"robocal/__init__.py": "", "robocal/kinematics/models.py": "", "robocal/diagnose/core.py": "",
             "robocal/diagnose/__init__.py": "from .core import diagnose\n",
             "robocal/diagnose/truth_cell.py": "from robocal.kinematics import chain\n",
             "robocal/simulation/__init__.py": "", "robocal/simulation/mock_cell.py": "",
             "robocal/simulation/truth_cell.py": "def f():\n    from . import mock_cell\n"}
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    assert "robocal.diagnose.core" in import_closure(tmp_path, "robocal.diagnose.truth_cell")
    assert import_closure(tmp_path, "robocal.simulation.truth_cell") == {
        "robocal", "robocal.simulation", "robocal.simulation.truth_cell", "robocal.simulation.mock_cell"}


@pytest.mark.unit
def test_truth_gravity_torque_on_j2_depends_on_q3_and_on_the_mount():
    camp = simulate([], 1, SMALL)
    mm = random_mass_model(camp.truth_kin, np.random.default_rng(0))
    q = np.zeros((2, 6))
    q[:, 1] = 0.3
    q[1, 2] = 0.8
    tau = gravity_torque_nm(camp.truth_kin, q, mm, np.zeros(2))
    assert abs(tau[0, 1] - tau[1, 1]) > 0.05 * abs(tau[0, 1])
    wall = gravity_torque_nm(camp.truth_kin, q, mm, np.zeros(2), down=(1.0, 0.0, 0.0))
    assert abs(wall[0, 0]) > 1.0 and abs(tau[0, 0]) < 1e-9         # a wall mount loads J1, a floor mount not


@pytest.mark.system
@pytest.mark.parametrize("truth,other", [("readback_lag", "backlash"), ("backlash", "readback_lag")])
def test_readback_lag_and_backlash_are_told_apart(truth, other):
    """Random move order, read-back joints only: the lag scales with the move, backlash saturates."""
    for seed in range(4):
        camp = simulate([truth], 300 + seed, SMALL)
        acc = accepted(diagnose(truth_input(camp)))
        assert truth in acc and other not in acc, (seed, camp.truths, list(acc))
        if truth == "readback_lag":
            got = acc[truth].evidence["physical"]["lag_deg_per_deg"]
            for j, lam in camp.truths[0].values["lag_per_move"].items():
                assert got[f"J{j}"] == pytest.approx(lam, abs=0.3 * abs(lam) + 5e-5)


@pytest.mark.system
@pytest.mark.parametrize("form", list(FORMS))
def test_the_failure_classes_of_real_campaigns_are_named(form):
    for seed in (900, 901):
        t = run_trial(form, FORMS[form][0], seed)
        print(form, seed, t.diagnosed, t.classes, t.confound)
        assert t.named_right and not t.lag_as_backlash, (form, seed, t.diagnosed, t.classes)
        if form in ("order_drift", "order_gear"):
            assert t.confound


@pytest.mark.system
def test_compliance_is_not_vetoed_next_to_misalignment_and_a_gear_term():
    """The small arm of the first real class: compliance is accepted with a positive stiffness however its
    parameters compare between near and far reach (that is reported, never used to drop it)."""
    t = run_trial("compound", FORMS["compound"][0], 910)
    assert "joint_compliance" in t.diagnosed


@pytest.mark.system
def test_a_part_pruned_before_a_larger_effect_was_taken_comes_back():
    """Lag + compliance, seed 6087 (the tenth protocol's breakdown): the lag is taken first and its J2 part looked
    unneeded while the larger compliance was unmodelled. Judged again from the lag as offered once compliance is in,
    J2 comes back, and no backlash takes its share; the test error reaches the noise floor."""
    t = run_trial("lag_compliance", FORMS["lag_compliance"][0], 6087)
    lag = t.diagnosed_joints[t.diagnosed.index("readback_lag")]
    assert tuple(lag) == (1, 2, 3) and not t.lag_as_backlash, (t.diagnosed, t.diagnosed_joints)
    assert t.final_test_rms_mm < 1.2 * t.noise_floor_mm


@pytest.mark.system
def test_reduced_self_check():
    """One seed per effect and per form, 3 controls, 2 two-effect cases, 1 out-of-library case."""
    result = run_self_check(seeds=1, controls=3, combos=2, outside=1)
    s = result.summary()
    print(s)
    assert s["single_trials"] == 8 and s["named_right"] == 8
    assert s["controls_clean"] == s["controls"] == 3
    assert s["lag_as_backlash"] == 0
    assert all(v["named_right"] == v["n"] for v in s["forms"].values())
    assert s["shrinkage_error_mm"]["mean_abs"] < 0.05
