"""A short kill study of ``campaign run`` (issue 36; the 100-kill study is ``bench/bench_kill.py``): SIGKILL at
seeded random instants, then ``--resume`` (or ``--overwrite`` where resume refuses): every directory recovers,
no point is lost or duplicated, and every file is complete or absent right after the kill."""
from __future__ import annotations

import pytest
import yaml

from tests.campaign.kill_study import study, summary
from tests.campaign.test_hostile_harms import few_point_doc

pytestmark = pytest.mark.system

KILLS = 6


def test_runs_killed_at_random_instants_recover_without_loss(tmp_path):
    doc = few_point_doc()
    doc["output"] = {"dir": str(tmp_path / "runs")}
    cfg = tmp_path / "small.yaml"
    cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
    trials = study(cfg, tmp_path, KILLS, seed=36)
    s = summary(trials)
    print(s)
    assert s["failed"] == 0 and s["lost"] == 0 and s["duplicated"] == 0 and s["torn"] == 0, trials
    assert len(s["phases"]) >= 3, s          # the instants spread over the run, not all in one phase
