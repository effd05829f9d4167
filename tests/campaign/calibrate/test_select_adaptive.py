"""``campaign select --adaptive`` is an honest replay: every batch is chosen from the measurements of the rows chosen
before it, never from a row it has not chosen or from a test row; and the CLI writes the subset and its rounds."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from campaign.calibrate.select_adaptive import adaptive_rows
from campaign.config.load import load_cell
from campaign.data.source import load_source
from robocal.simulation.truth_cell import TruthProtocol, simulate
from tests.campaign.helpers import truth_csv
from tests.campaign.hostile import cli

pytestmark = pytest.mark.system

N = 42


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    camp = simulate(["joint_compliance", "gear_cyclic"], 7, TruthProtocol(n_calib=150, n_test=40, check_poses=4,
                                                                          check_repeats=3))
    csv, cfg = truth_csv(tmp_path_factory.mktemp("adaptive"), camp)
    return csv, cfg, load_source(csv).dataset, load_cell(cfg)


@pytest.mark.parametrize("rule", ["f", "d"])
def test_a_batch_never_sees_the_rows_it_has_not_chosen(campaign, rule):
    """Under the default rule ``f`` the poses follow from the poses alone and the measurements of the chosen rows
    judge every round (its predicted held-out RMS, hence the stop); under the model-driven ``d`` they also steer
    the picks. Neither ever reads a row it has not chosen."""
    _, _, ds, cell = campaign
    sel = adaptive_rows(ds, cell, N, rule=rule)
    assert len(sel.order) == len(set(sel.order)) == N and len(sel.rounds) == 2
    assert [len(r.added) for r in sel.rounds] == [10, N - sel.n_seed - 10]
    rng = np.random.default_rng(3)
    unseen = ~np.isin(np.arange(len(ds)), sel.order) & (ds.mask("calib") | ds.mask("test"))
    p = ds.p_tracker_mm.copy()
    p[unseen] += rng.normal(0.0, 0.3, (int(unseen.sum()), 3))      # other errors where it never looked
    again = adaptive_rows(replace(ds, p_tracker_mm=p), cell, N, rule=rule)
    np.testing.assert_array_equal(again.order, sel.order)
    assert [r.predicted_rms_mm for r in again.rounds] == [r.predicted_rms_mm for r in sel.rounds]
    seen = sel.order[: sel.n_seed]                                  # the seed's own measurements judge the rounds
    p = ds.p_tracker_mm.copy()
    p[seen] += rng.normal(0.0, 0.3, (len(seen), 3))
    moved = adaptive_rows(replace(ds, p_tracker_mm=p), cell, N, rule=rule)
    np.testing.assert_array_equal(moved.order[: sel.n_seed], sel.order[: sel.n_seed])
    assert moved.rounds[0].predicted_rms_mm != pytest.approx(sel.rounds[0].predicted_rms_mm, rel=1e-3)
    assert np.array_equal(moved.order, sel.order) == (rule == "f")


def test_select_adaptive_cli_writes_the_subset_and_its_rounds(campaign, tmp_path, capsys):
    csv, cfg, ds, _ = campaign
    code, out, err = cli(capsys, "select", csv, "--config", cfg, "--points", N, "--adaptive", "--out",
                         tmp_path / "sub.csv")
    assert code == 0, err
    sub = load_source(tmp_path / "sub.csv").dataset
    assert int(sub.mask("calib").sum()) == N and int(sub.mask("test").sum()) == int(ds.mask("test").sum())
    assert f"selected {N} of {int(ds.mask('calib').sum())} calibration rows (adaptive" in out and "Rounds" in out


def test_with_a_task_the_replay_picks_the_task_first(campaign, tmp_path):
    """With ``plan.task`` in the config, the rounds' picks cover it: after the seed, rows whose SMR is in the box
    (the box of the middle of the calibration SMRs), until the box is used up; without it, they spread."""
    import yaml

    from campaign.calibrate.select_adaptive import adaptive_selection
    from robocal.kinematics.models import smr_base

    _, cfg, ds, cell = campaign
    cal = np.flatnonzero(ds.mask("calib"))
    p = smr_base(cell.kinematics, np.radians(ds.q_deg))
    lo, hi = np.percentile(p[cal], 25, axis=0), np.percentile(p[cal], 75, axis=0)
    doc = yaml.safe_load(cfg.read_text())
    doc.setdefault("plan", {})["task"] = {"box_mm": [lo.tolist(), hi.tolist()]}
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(doc))
    inside = lambda rows: np.all((p[rows] >= lo) & (p[rows] <= hi), axis=1)       # noqa: E731
    n_box = int(inside(cal).sum())
    shares = {}
    for c in (cell, load_cell(tmp_path / "task.yaml")):
        sel = adaptive_selection(ds, c, N)
        after = sel.order[sel.n_seed:]
        free_in_box = n_box - int(inside(sel.order[:sel.n_seed]).sum())
        shares[c is cell] = float(np.mean(inside(after[:min(len(after), free_in_box)])))
    assert shares[False] == 1.0 and shares[True] < 0.5, shares
