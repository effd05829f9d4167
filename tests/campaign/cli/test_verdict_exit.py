"""A verdict a machine can read: an acceptance FAIL exits 4 (distinct from every error code) with every output
written, for ``run`` and ``reprocess``; a bound below the noise floor is warned about before measuring (``validate``,
``plan``, ``run``) and noted in the report. The same small run serves ``verify`` (which needs a run's directory, not
a reprocess output) and ``export --urdf`` (which takes the run's own config)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from campaign.cli.boundary import EXIT_ACCEPTANCE_FAIL, EXIT_BAD_INPUT, EXIT_CRASH, EXIT_FAILED, EXIT_INTERRUPTED
from tests.campaign.helpers import ROOT, small_config
from tests.campaign.hostile import cli, run_campaign_process

pytestmark = pytest.mark.system

FAST = {"calibration.effects": "none", "calibration.residual": "none", "plan.grid.step_mm": 500,
        "plan.test.count": 20}
TIGHT = {"max_rms_mm": 0.001}                  # far below the cell's noise floor (about 0.03 mm)


@pytest.fixture(scope="module")
def failed_run(tmp_path_factory):
    """``campaign run`` of a small mock cell whose criterion no model can meet: (run dir, stdout, stderr, code)."""
    tmp = tmp_path_factory.mktemp("verdict")
    cfg = small_config(tmp, acceptance=TIGHT, **FAST)
    code, out, err = run_campaign_process(["run", cfg, "--out", tmp / "run"], tmp, env={"COLUMNS": "1000"})
    return tmp / "run", out, err, code


def test_the_fail_code_is_distinct_from_every_error_code():
    assert EXIT_ACCEPTANCE_FAIL == 4
    assert EXIT_ACCEPTANCE_FAIL not in (0, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_CRASH, EXIT_INTERRUPTED)


def test_run_warns_before_measuring_then_fails_with_exit_4_and_writes_every_output(failed_run):
    run, out, err, code = failed_run
    assert code == EXIT_ACCEPTANCE_FAIL, err
    assert "Traceback" not in out + err
    warning = "acceptance.max_rms_mm 0.001 mm is below the noise floor"
    assert out.index(warning) < out.index("verdict: FAIL")            # printed before anything was measured
    assert warning in (run / "campaign.log").read_text()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("acceptance FAIL (max_rms_mm exceeded") and str(run) in lines[0]
    for name in ("log.jsonl", "data.csv", "report.json", "model.json", "report.html"):
        assert (run / name).is_file(), name
    verdict = json.loads((run / "report.json").read_text())["summary"]["verdict"]
    assert verdict["result"] == "fail" and verdict["below_noise"] == ["max_rms_mm"]
    assert "note: a perfect model would fail this bound more often than not: RMS bound below the noise floor" in out


def test_reprocess_of_the_run_exits_4_on_fail_with_every_output_written(failed_run, tmp_path):
    """(A PASS exits 0: the demo's run and reprocess in tests/campaign/test_workflows.py.)"""
    run = failed_run[0]
    tight = small_config(tmp_path, acceptance=TIGHT, **FAST)
    code, out, err = run_campaign_process(["reprocess", run, "--config", tight, "--out", tmp_path / "fail"], tmp_path)
    assert code == EXIT_ACCEPTANCE_FAIL and "verdict: FAIL" in out
    assert len(err.strip().splitlines()) == 1 and "acceptance FAIL" in err
    assert {"report.json", "model.json", "report.html"} <= {p.name for p in (tmp_path / "fail").iterdir()}
    report = json.loads((tmp_path / "fail" / "report.json").read_text())
    assert report["robot_identity"]["serial"] and "provenance" not in report      # a log keeps its devices

    code, _, err = run_campaign_process(["verify", tmp_path / "fail"], tmp_path)  # no robot measured a reprocess
    assert code == EXIT_BAD_INPUT and len(err.strip().splitlines()) == 1
    assert "written by campaign reprocess" in err and "config.yaml, log.jsonl, model.json" in err
    assert "file not found" not in err


def test_validate_and_plan_warn_about_a_bound_below_the_predicted_floor(tmp_path, capsys):
    tight = small_config(tmp_path, acceptance={"max_rms_mm": 0.001, "max_mm": 0.002})
    code, out, err = run_campaign_process(["validate", tight], tmp_path)
    assert code == 0 and out.startswith("OK ")
    lines = err.strip().splitlines()
    assert len(lines) == 2 and all(line.startswith("warning: acceptance.max") for line in lines), lines
    assert "below the noise floor: the noise floor the specs predict at the config's 30 test points" in lines[0]
    assert "the median largest of 30 errors of noise alone" in lines[1]
    code, out, err = cli(capsys, "plan", tight)
    assert code == 0 and err.count("warning: acceptance.") == 2
    planned = re.search(r"at the plan's (\d+) test points is (\d\.\d{3}) mm", err)          # its test points, the floor
    assert planned and f"noise floor {planned[2]} mm" in " ".join(out.split())  # its forecast prints
    code, out, err = run_campaign_process(["validate", ROOT / "configs" / "irb2600.yaml"], tmp_path)
    assert code == 0 and err == ""                  # the demo's criterion sits above its floor


def test_export_urdf_takes_the_config_of_the_run_that_wrote_the_model(failed_run, tmp_path):
    run = failed_run[0]
    code, out, err = run_campaign_process(["export", run / "model.json", "--urdf", tmp_path / "r.urdf"], tmp_path)
    assert code == 0, err
    assert f"from {run / 'config.yaml'}" in " ".join(out.split()) and (tmp_path / "r.urdf").is_file()
    assert 'lower="-3.14159' in (tmp_path / "r.urdf").read_text()              # J1's limits of the run's config
    alone = tmp_path / "elsewhere.json"
    alone.write_bytes((run / "model.json").read_bytes())
    code, _, err = run_campaign_process(["export", alone, "--urdf", tmp_path / "x.urdf"], tmp_path)
    assert code == EXIT_BAD_INPUT and "give --config CONFIG" in err and not (tmp_path / "x.urdf").exists()
