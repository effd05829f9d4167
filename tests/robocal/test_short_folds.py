"""The effect selection's folds on few rows (``robocal.effects.select.SHORT_ROWS``; issue 32's nineteenth protocol,
bench/bench_short_folds.py)."""
from __future__ import annotations

from unittest import mock

import pytest

import robocal.effects.select as select

pytestmark = pytest.mark.unit


def test_below_the_row_count_the_selection_uses_at_least_the_short_folds():
    with mock.patch.multiple(select, SHORT_ROWS=100, SHORT_FOLDS=10):
        assert [select.short_folds(5, n) for n in (30, 99, 100, 300)] == [10, 10, 5, 5]
        assert select.short_folds(12, 50) == 12                  # more folds asked for: kept


def test_without_a_row_count_the_folds_asked_for():
    with mock.patch.object(select, "SHORT_ROWS", None):
        assert [select.short_folds(5, n) for n in (30, 300)] == [5, 5]


@pytest.mark.parametrize("n_calib, folds", [(60, 10), (120, 5)])
def test_the_selection_cross_validates_with_the_short_folds_below_the_row_count(n_calib, folds):
    from robocal.simulation.truth_cell import TruthProtocol, simulate
    from tests.robocal.test_elastic import engine_on

    camp = simulate([], 21, TruthProtocol(n_calib=n_calib, n_test=20, check_poses=4, check_repeats=3))
    with mock.patch.multiple(select, SHORT_ROWS=100, SHORT_FOLDS=10):
        eng = engine_on(camp)[-1]
    assert eng.selection.folds == folds
    assert eng.selection.to_dict()["method"].startswith(f"forward selection, {folds}-fold")
