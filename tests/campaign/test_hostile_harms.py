"""The eight harms of the hostile-neighbour audit (issue 36), each reproduced as it was found: the real entry point
(``python -m campaign``) in a fresh directory, with the exit code, exactly one stderr line where the command must
refuse, the checksums of files that are not the command's, and no secret in any byte written.

1. a password holding ``/``, ``#`` or ``?`` in a driver URL;  2. formula cells in points.csv;  3. two writers of
one output directory;  4. ``--overwrite`` over a device node or FIFO;  5. a link planted at a temporary name;
6. a run killed at its start;  7. a run killed while its figures directory is made;  8. ``diagnose`` of a live run.
Also: an integer too long to read in a config or a log line, and stale temporaries of a killed writer.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from campaign.run.log_reader import LOG_NAME
from tests.campaign.helpers import geometric_only, ROOT
from tests.campaign.hostile import (assert_one_line, barrier_code, checksums, finish, kill_code, run_campaign_process,
                                    start_campaign_process)

pytestmark = pytest.mark.system

PASSWORD_URLS = {  # (config key, url): each password holds a character urlsplit stops at
    "slash": ("robot.url", "abb-rws://calib:pa/ss-S3cr3t@127.0.0.1:9"),
    "digits_then_slash": ("robot.url", "abb-rws://calib:2024/S3cr3t-pw@192.0.2.10"),
    "mock": ("robot.url", "mock://calib:pa/ss-S3cr3t@robot"),
    "hash": ("tracker.url", "emscon://calib:pa#ss-S3cr3t@192.0.2.11"),
    "query": ("robot.url", "ur-rtde://calib:pa?ss-S3cr3t@192.0.2.12"),
}
SECRET_PART = "S3cr3t"


def few_point_doc() -> dict:
    """The demo cell, geometric only, with a 3 x 3 x 2 grid and three test points: a run of a few seconds."""
    doc = geometric_only(yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text()))
    doc["plan"]["grid"] = {"center_mm": [900, 0, 1000], "size_mm": [800, 800, 400], "step_mm": 400}
    doc["plan"]["test"] = {"count": 3, "seed": 0}
    doc["plan"]["check_poses"] = {"count": 0, "every_n_points": 50}
    return doc


def write_config(path: Path, doc: dict) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> dict:
    """A small config and one finished run of it (for the commands that read a run)."""
    root = tmp_path_factory.mktemp("harms")
    doc = few_point_doc()
    doc["output"] = {"dir": str(root / "runs")}
    cfg = write_config(root / "small.yaml", doc)
    code, _, err = run_campaign_process(["run", cfg, "--out", root / "run"], root)
    assert code == 0, err
    return {"root": root, "doc": doc, "config": cfg, "run": root / "run"}


def no_secret(root: Path, *texts: str) -> list[str]:
    hits = [f"output {i}" for i, t in enumerate(texts) if SECRET_PART in t]
    return hits + [str(p) for p in root.rglob("*") if p.is_file() and p.suffix != ".yaml"
                   and SECRET_PART.encode() in p.read_bytes()]


# ------------------------------------------------------------------------------------------ 1. secrets in URLs

@pytest.mark.parametrize("case", sorted(PASSWORD_URLS))
def test_a_password_with_url_characters_is_refused_and_never_shown(small, tmp_path, case):
    key, url = PASSWORD_URLS[case]
    doc = json.loads(json.dumps(small["doc"]))
    doc[key.split(".")[0]]["url"] = url
    doc["output"] = {"dir": str(tmp_path / "runs")}
    cfg = write_config(tmp_path / "cfg.yaml", doc)
    for argv in (["validate", cfg], ["plan", cfg], ["run", cfg, "--out", tmp_path / "run"]):
        code, out, err = run_campaign_process(argv, tmp_path)
        assert_one_line(code, out, err, 2, key, "credentials in the URL are refused")
        assert not no_secret(tmp_path, out, err), (argv[0], no_secret(tmp_path, out, err))
    assert not (tmp_path / "run").exists() and not (tmp_path / "runs").exists()


# --------------------------------------------------------------------------------- 2. formula cells in points.csv

FORMULA_IDS = ["=cmd|' /C calc'!A0", "+SUM(A1)", "-2+3", "@SUM(1)", "=1+1"]


def test_points_csv_never_holds_a_formula_cell(small, tmp_path):
    rows = list(csv.reader((small["run"] / "data.csv").read_text().splitlines()))
    calib = [r for r in rows[1:] if r[1] == "calib"]
    for r, pid in zip(calib, FORMULA_IDS):
        r[0] = pid
    src = tmp_path / "formulas.csv"
    with open(src, "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    code = ("import sys\nimport campaign.calibrate.report_points as rp\nrp.POINTS_INLINE_MAX = 2\n"   # side file
            "from campaign.cli import main\nsys.exit(main())\n")
    out_dir = tmp_path / "out"
    status, out, err = run_campaign_process(["reprocess", src, "--config", small["config"], "--out", out_dir],
                                            tmp_path, code=code)
    assert status == 0, err
    table = list(csv.reader((out_dir / "points.csv").read_text().splitlines()))
    ids = [r[-1] for r in table[1:]]
    assert all(pid in ids for pid in ("'" + p for p in FORMULA_IDS if not p.startswith("-2"))), ids[:8]
    formulas = [c for r in table[1:] for c in r if c[:1] in "=+-@\t\r" and not _number(c)]
    assert not formulas, formulas
    from campaign.calibrate.report_points import PointTable
    back = PointTable.of(json.loads((out_dir / "report.json").read_text())["points"], out_dir)
    assert set(FORMULA_IDS) <= set(back.point_id)            # read back as written


def _number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


# ------------------------------------------------------------------------------------ 3. ownership under races

def _second_source(small, tmp_path) -> Path:
    rows = (small["run"] / "data.csv").read_text().splitlines()
    other = tmp_path / "other.csv"
    other.write_text("\n".join(rows) + "\n# another source\n")
    return other


def test_a_writer_that_finished_meanwhile_is_not_replaced(small, tmp_path):
    out_dir, ready, go = tmp_path / "X", tmp_path / "ready", tmp_path / "go"
    first = start_campaign_process(["reprocess", small["run"] / "data.csv", "--config", small["config"], "--out",
                                    out_dir], tmp_path,
                                   code=barrier_code("campaign.run.output_dirs", "Claim.take", ready, go))
    _wait_for(ready, first)
    code, out, err = run_campaign_process(["reprocess", _second_source(small, tmp_path), "--config",
                                           small["config"], "--out", out_dir], tmp_path)
    assert code == 0, err
    (out_dir / "notes.txt").write_text("the engineer's notes\n")
    before = checksums(out_dir)
    go.touch()
    code, out, err = finish(first)
    assert_one_line(code, out, err, 2, str(out_dir), "other.csv")
    assert checksums(out_dir) == before


def test_two_writers_of_one_new_directory_one_is_refused(small, tmp_path):
    out_dir, go = tmp_path / "X", tmp_path / "go"
    sources = [small["run"] / "data.csv", _second_source(small, tmp_path)]
    procs = [start_campaign_process(["reprocess", src, "--config", small["config"], "--out", out_dir], tmp_path,
                                    code=barrier_code("campaign.run.output_dirs", "Claim.take", tmp_path / f"r{i}",
                                                      go)) for i, src in enumerate(sources)]
    for i, proc in enumerate(procs):
        _wait_for(tmp_path / f"r{i}", proc)
    go.touch()
    results = [finish(p) for p in procs]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], [r[2] for r in results]
    loser = next(r for r in results if r[0] == 2)
    assert_one_line(*loser, 2, str(out_dir))
    winner = sources[[r[0] for r in results].index(0)]
    marker = json.loads((out_dir / ".campaign-owner.json").read_text())
    assert marker["source"] == str(winner.resolve())
    assert json.loads((out_dir / "report.json").read_text())["source"].endswith(winner.name)


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 240) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        if proc.poll() is not None:
            raise AssertionError(f"exited {proc.returncode} before the barrier: {proc.stderr.read().decode()}")
        assert time.monotonic() < deadline, "the barrier was never reached"
        time.sleep(0.05)


# ------------------------------------------------------------------------ 4. device nodes and FIFOs are no files

def _specials(d: Path) -> list[Path]:
    d.mkdir()
    os.mkfifo(d / "fifo")
    nodes = [d / "fifo"]
    if os.geteuid() == 0:                               # CI runs as root: a character device too (/dev/null's)
        os.mknod(d / "devnull", stat.S_IFCHR | 0o666, os.makedev(1, 3))
        nodes.append(d / "devnull")
    return nodes


def test_overwrite_never_replaces_a_device_or_a_fifo(small, tmp_path):
    nodes = _specials(tmp_path / "D")
    ur5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
    calib = sorted(ur5.rglob("*.csv"))[0]
    for node in nodes:
        kinds = {node: os.lstat(node).st_mode}
        for argv, option in ((["select", small["run"], "--config", small["config"], "--points", "4", "--out", node],
                              "--out"),
                             (["export", small["run"] / "model.json", "--urdf", node, "--config", small["config"]],
                              "--urdf"),
                             (["import", "target-dif", calib, "--out", node], "--out")):
            code, out, err = run_campaign_process([*argv, "--overwrite"], tmp_path)
            assert_one_line(code, out, err, 2, str(node), "not a regular file")
            assert os.lstat(node).st_mode == kinds[node], argv[0]


# -------------------------------------------------------------------- 5. a link planted at a temporary name

def test_a_planted_link_at_a_temporary_name_is_never_written_through(small, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small["run"], run)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    names = ("report.html", "report.json", "index.html")
    plant = (f"import os, sys\n"
             f"for name in {names!r}:\n"
             f"    os.symlink({str(victim)!r}, os.path.join({str(run)!r}, '.%s.%d.tmp' % (name, os.getpid())))\n"
             f"from campaign.cli import main\nsys.exit(main())\n")
    code, out, err = run_campaign_process(["report", run], tmp_path, code=plant)
    assert code == 0, err
    assert victim.read_text() == "precious\n"
    assert (run / "report.html").is_file() and not (run / "report.html").is_symlink()


# ------------------------------------------------------------------------ 6. a run killed at its start

KILL_POINTS = {  # where the start of a run is cut: (module, attribute, after it returned?)
    "after_the_marker": ("campaign.run.output_dirs", "Claim.take", True),
    "after_the_config_copy": ("campaign.run.session", "copy_config", True),
    "after_the_log": ("campaign.run.log_writer", "RunLog.create", True),
}


@pytest.mark.parametrize("where", sorted(KILL_POINTS))
@pytest.mark.parametrize("how", ["resume", "overwrite"])
def test_a_run_killed_at_its_start_is_resumed_or_redone(small, tmp_path, where, how):
    run = tmp_path / "run"
    code, _, err = run_campaign_process(["run", small["config"], "--out", run], tmp_path, code=kill_code(*KILL_POINTS[where]))
    assert code == -9, err
    if how == "overwrite" and (run / LOG_NAME).exists():      # a log: the run's evidence, resumed only
        code, out, err = run_campaign_process(["run", small["config"], "--out", run, "--overwrite"], tmp_path)
        assert_one_line(code, out, err, 2, "--resume")
        how = "resume"
    argv = ["--resume", run] if how == "resume" else ["--out", run, "--overwrite"]
    code, out, err = run_campaign_process(["run", small["config"], *argv], tmp_path)
    assert code == 0, err
    _complete_once(run, small["run"])


def _complete_once(run: Path, reference: Path) -> None:
    """Every plan point measured exactly once, and the outputs of a finished run."""
    ids = [json.loads(line)["data"]["point_id"] for line in (run / LOG_NAME).read_text().splitlines()
           if json.loads(line)["kind"] == "point"]
    expected = [json.loads(line)["data"]["point_id"] for line in (reference / LOG_NAME).read_text().splitlines()
                if json.loads(line)["kind"] == "point"]
    assert sorted(ids) == sorted(expected)
    for name in ("report.json", "model.json", "report.html", "plan.csv", "config.yaml"):
        assert (run / name).is_file(), name


# ------------------------------------------------------------- 7. a run killed while its figures directory is made

def test_a_run_killed_while_its_figures_directory_is_made_resumes(small, tmp_path):
    run = tmp_path / "run"
    kill = ("import os, signal, sys\n"
            "import campaign.io.durable as od\n"              # the marker's temporary file (create_new)
            "orig = od.create_temp\n"
            "def create_temp(path, *a, **k):\n"
            "    out = orig(path, *a, **k)\n"
            "    if path.parent.name.endswith('_figures'):\n"
            "        os.kill(os.getpid(), signal.SIGKILL)\n"
            "    return out\n"
            "od.create_temp = create_temp\n"
            "from campaign.cli import main\nsys.exit(main())\n")
    code, _, err = run_campaign_process(["run", small["config"], "--out", run], tmp_path, code=kill)
    assert code == -9, err
    assert list((run / "report_figures").glob(".*.tmp")), "the kill did not land inside the figures directory"
    code, out, err = run_campaign_process(["run", small["config"], "--resume", run], tmp_path)
    assert code == 0, err
    _complete_once(run, small["run"])
    assert not list((run / "report_figures").glob(".*.tmp"))


# ----------------------------------------------------------------------------- 8. diagnose of a live run

def test_diagnose_and_report_never_write_into_a_live_run(small, tmp_path):
    run, ready, go = tmp_path / "run", tmp_path / "ready", tmp_path / "go"
    live = start_campaign_process(["run", small["config"], "--out", run], tmp_path,
                                  code=barrier_code("campaign.calibrate.stages", "calibrate_dataset", ready, go))
    _wait_for(ready, live)                              # measured, logged, calibrating
    before = checksums(run)
    for argv in (["diagnose", run, "--config", run / "config.yaml"], ["report", run]):
        code, out, err = run_campaign_process(argv, tmp_path)
        assert_one_line(code, out, err, 2, str(run), "live")
        assert checksums(run) == before, argv[0]
    go.touch()
    code, out, err = finish(live)
    assert code == 0, err


# ------------------------------------------------------------------------- huge numbers, stale temporaries

def test_an_integer_too_long_to_read_is_one_input_error(small, tmp_path):
    text = small["config"].read_text().replace("step_mm: 400", "step_mm: " + "9" * 5000, 1)
    cfg = tmp_path / "big.yaml"
    cfg.write_text(text)
    code, out, err = run_campaign_process(["validate", cfg], tmp_path)
    assert_one_line(code, out, err, 2, "too many digits")
    run = tmp_path / "run"
    shutil.copytree(small["run"], run)
    lines = (run / LOG_NAME).read_text().splitlines()
    (run / LOG_NAME).write_text("\n".join(lines[:3] + ['{"kind":"point","seq":' + "9" * 5000 + "}"]) + "\n")
    code, out, err = run_campaign_process(["reprocess", run, "--config", small["config"], "--out", tmp_path / "o"],
                                          tmp_path)
    assert_one_line(code, out, err, 2, LOG_NAME)


def test_a_later_successful_write_removes_the_temporaries_of_a_killed_writer(small, tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    out_dir = tmp_path / "out"
    code, _, err = run_campaign_process(["reprocess", small["run"], "--config", small["config"], "--out", out_dir],
                                        tmp_path)
    assert code == 0, err
    stale = [out_dir / f".model.json.{pid}.tmp", out_dir / f".report.json.{pid}.0a1b2c.tmp"]
    for path in stale:
        path.write_text("half a model")
    code, _, err = run_campaign_process(["reprocess", small["run"], "--config", small["config"], "--out", out_dir],
                                        tmp_path)
    assert code == 0, err
    assert not any(p.exists() for p in stale)
