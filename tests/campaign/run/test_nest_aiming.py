"""Reference nests on a tracker that cannot find a nest by itself: a config error naming the key, before any move
(it used to be a TypeError in the middle of the run)."""
from __future__ import annotations

import dataclasses

import pytest

from campaign.config.load import load_config
from campaign.config.plan_schema import NestConfig
from campaign.errors import ConfigError
from campaign.run.session import check_nest_aiming
from tests.campaign.helpers import ROOT

pytestmark = pytest.mark.unit


class _LineTracker:                 # the line-protocol and emScon drivers: reacquire(xyz), no select_nest
    def reacquire(self, p_tracker_mm):
        raise AssertionError("not called by the check")


class _MockTracker(_LineTracker):
    def select_nest(self, nest_id, guess=None):
        pass


def _with_nests(*nests: NestConfig):
    cfg = load_config(ROOT / "configs" / "irb2600.yaml")
    plan = dataclasses.replace(cfg.plan, nests=dataclasses.replace(cfg.plan.nests, points=nests))
    return dataclasses.replace(cfg, plan=plan)


def test_a_nest_without_its_tracker_position_is_a_config_error_on_a_tracker_that_cannot_search():
    cfg = _with_nests(NestConfig("N1", (0.0, 900.0, 0.0), (1.0, 2.0, 3.0)), NestConfig("N2", (0.0, -900.0, 0.0)))
    with pytest.raises(ConfigError, match=r"plan\.nests\.points\[1\]\.p_tracker_mm: nest 'N2'"):
        check_nest_aiming(cfg, _LineTracker())


def test_nests_with_tracker_positions_or_a_tracker_that_searches_pass():
    check_nest_aiming(_with_nests(NestConfig("N1", (0.0, 900.0, 0.0), (1.0, 2.0, 3.0))), _LineTracker())
    check_nest_aiming(_with_nests(NestConfig("N1", (0.0, 900.0, 0.0))), _MockTracker())
