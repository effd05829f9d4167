"""A joint's low harmonics offered one at a time beside the set (``robocal.effects.library.SINGLE_HARMONICS``, off by
default: the sixteenth protocol of issue 32 did not keep it; bench/bench_single_harmonics.py switches it on): which
candidates the library offers, and which of them a taken one retires (``robocal.effects.select.alternatives``)."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest

import robocal.effects.library as library
from robocal.effects.library import LibraryOptions, candidates
from robocal.effects.select import alternatives
from robocal.kinematics.gravity import GravityModel
from robocal.simulation.truth_cell import irb2600_nominal


def _candidates(q_deg: np.ndarray, singles: bool = True) -> list:
    with mock.patch.object(library, "SINGLE_HARMONICS", singles):
        return candidates(irb2600_nominal(), np.radians(q_deg), {}, GravityModel.of_robot(6))[0]


def _gears(q_deg: np.ndarray, singles: bool = True) -> list[str]:
    return [c.label for c in _candidates(q_deg, singles) if c.name == "gear_cyclic"]


def _poses(span_deg: float, n: int = 60) -> np.ndarray:
    """n poses, every joint spread over ``span_deg`` around zero (seeded)."""
    return np.random.default_rng(3).uniform(-span_deg / 2, span_deg / 2, (n, 6))


@pytest.mark.unit
def test_each_low_harmonic_is_offered_alone_beside_the_set():
    labels = _gears(_poses(300.0))
    for j in range(1, 7):
        assert f"gear_cyclic(J{j} h1,2,3,4)" in labels
        assert [f"gear_cyclic(J{j} h{h})" in labels for h in (1, 2, 3, 4)] == [True] * 4
    sets = [f"gear_cyclic(J{j} h1,2,3,4)" for j in range(1, 7)]
    assert _gears(_poses(300.0), singles=False) == sets
    assert not library.SINGLE_HARMONICS and [c.label for c in candidates(
        irb2600_nominal(), np.radians(_poses(300.0)), {}, GravityModel.of_robot(6))[0] if c.name == "gear_cyclic"] == sets


@pytest.mark.unit
def test_a_joint_offered_one_harmonic_gets_no_duplicate_single():
    """Over 60 degrees a joint is offered harmonic 1 only (``degrees_per_harmonic`` 45): the set is that single."""
    labels = _gears(_poses(60.0))
    assert LibraryOptions().degrees_per_harmonic == 45.0
    assert labels == [f"gear_cyclic(J{j} h1)" for j in range(1, 7)]     # h1 alone: one candidate per joint


@pytest.mark.unit
def test_a_taken_single_retires_the_set_and_its_order_but_not_the_other_orders():
    cands = _candidates(_poses(300.0))
    j4 = {c.label: c for c in cands if c.name == "gear_cyclic" and dict(c.options)["joint"] == 4}
    single = j4["gear_cyclic(J4 h2)"]
    assert alternatives(j4["gear_cyclic(J4 h1,2,3,4)"], single)
    assert not any(alternatives(j4[f"gear_cyclic(J4 h{h})"], single) for h in (1, 3, 4))
    j5_h2 = next(c for c in cands if c.label == "gear_cyclic(J5 h2)")
    assert not alternatives(j5_h2, single)                               # another joint's error is another effect
