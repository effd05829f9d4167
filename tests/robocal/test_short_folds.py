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
