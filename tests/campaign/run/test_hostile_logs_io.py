"""Hostile run logs and I/O faults (issue 12).

Logs: records with a valid CRC but bad content, broken structure, missing files. ``run --resume`` must refuse
them with exit 2 and one line BEFORE anything moves (the log is left byte-identical: not even a resume event).
I/O: missing paths, read-only output directory, disk full (patched ``os.write`` in-process, RLIMIT_FSIZE in a
subprocess), an internal error (crash report, exit 3), and SIGTERM / SIGHUP / Ctrl-C during a run.
"""
from __future__ import annotations

import errno
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from campaign.run.output_dirs import MARKER
from campaign.run.log_reader import encode_record, read_log
from tests.campaign.helpers import ROOT, small_config
from tests.campaign.hostile import assert_one_line, cli, snapshot

KEEP_POINTS = 12          # the interrupted run keeps this many point records


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A finished small run, and the log lines of an interrupted copy (start + KEEP_POINTS points, no stop)."""
    from campaign.cli import main

    root = tmp_path_factory.mktemp("hostile-log")
    cfg = small_config(root, "irb2600")
    run = root / "run"
    assert main(["run", str(cfg), "--out", str(run)]) == 0
    lines = (run / "log.jsonl").read_bytes().splitlines(keepends=True)
    assert json.loads(lines[0])["kind"] == "start"
    points = [json.loads(ln) for ln in lines[1:] if json.loads(ln)["kind"] == "point"][:KEEP_POINTS]
    assert len(points) == KEEP_POINTS
    # start + the first points only (events such as the devices record left out), numbered again: the cases
    # below address point records by line number
    first = json.loads(lines[0])["seq"] + 1
    kept = [lines[0]] + [encode_record("point", seq, rec["data"]) for seq, rec in enumerate(points, start=first)]
    return {"config": cfg, "run": run, "lines": kept}


def _interrupted(tmp: Path, base: dict, lines: list[bytes] | None = None) -> Path:
    """A run directory whose log is ``lines`` (default: the interrupted prefix)."""
    run = tmp / "run"
    run.mkdir()
    for name in ("config.yaml", "plan.csv"):
        shutil.copy(base["run"] / name, run / name)
    (run / "log.jsonl").write_bytes(b"".join(base["lines"] if lines is None else lines))
    return run


def _edit(line_no: int, fn: Callable[[dict], None]) -> Callable[[list[bytes]], list[bytes]]:
    """Change the data of record ``line_no`` (1-based) and re-encode it with a VALID crc."""
    def apply(lines: list[bytes]) -> list[bytes]:
        rec = json.loads(lines[line_no - 1])
        fn(rec["data"])
        lines[line_no - 1] = encode_record(rec["kind"], rec["seq"], rec["data"])
        return lines
    return apply


def _set(key: str, value) -> Callable[[dict], None]:
    def apply(d: dict) -> None:
        d[key] = value
    return apply


def _pop(key: str) -> Callable[[dict], None]:
    return lambda d: d.pop(key)


def _duplicate(lines: list[bytes]) -> list[bytes]:
    rec = json.loads(lines[3])
    return lines + [encode_record("point", len(lines), rec["data"])]


def _bad_crc(lines: list[bytes]) -> list[bytes]:
    lines[4] = lines[4].replace(b'"crc":"', b'"crc":"0', 1)[:-11] + b'"}\n'
    return lines


def _seq_gap(lines: list[bytes]) -> list[bytes]:
    return lines[:5] + lines[6:]


@dataclass(frozen=True)
class LogCase:
    edit: Callable[[list[bytes]], list[bytes]] | None = None
    needles: tuple[str, ...] = ()
    raw: bytes | None = None


LOG_CASES: dict[str, LogCase] = {
    "q_cmd_differs_from_plan": LogCase(_edit(3, lambda d: d["q_cmd_deg"].__setitem__(1, d["q_cmd_deg"][1] + 5)),
                                       ("line 3", "q_cmd_deg differs")),
    "point_id_not_in_plan": LogCase(_edit(4, _set("point_id", "ZZZ")), ("line 4", "not in the run's plan")),
    "point_id_integer": LogCase(_edit(4, _set("point_id", 17)), ("line 4", "point_id")),
    "point_id_200_chars": LogCase(_edit(4, _set("point_id", "P" * 200)), ("line 4",)),
    "point_measured_twice": LogCase(_duplicate, ("measured twice",)),
    "xyz_1e300": LogCase(_edit(5, _set("p_tracker_mm", [1e300, 0.0, 0.0])), ("line 5", "p_tracker_mm")),
    "xyz_strings": LogCase(_edit(5, _set("p_tracker_mm", ["a", "b", "c"])), ("line 5", "p_tracker_mm")),
    "xyz_missing": LogCase(_edit(5, _pop("p_tracker_mm")), ("line 5", "p_tracker_mm")),
    "xyz_two_values": LogCase(_edit(5, _set("p_tracker_mm", [1.0, 2.0])), ("line 5", "p_tracker_mm")),
    "q_read_wrong_length": LogCase(_edit(6, _set("q_read_deg", [0.0] * 5)), ("line 6", "q_read_deg")),
    "q_read_1000_deg": LogCase(_edit(6, lambda d: d["q_read_deg"].__setitem__(1, 1000.0)), ("line 6", "limits")),
    "q_read_null": LogCase(_edit(6, _set("q_read_deg", None)), ("line 6", "q_read_deg")),
    "set_bogus": LogCase(_edit(7, _set("set", "bogus")), ("line 7", "set")),
    "set_differs_from_plan": LogCase(_edit(7, lambda d: d.__setitem__("set", "test" if d["set"] != "test"
                                                                      else "calib")), ("line 7", "the plan says")),
    "cov_wrong_shape": LogCase(_edit(8, _set("cov_mm2", [[1.0, 0.0], [0.0, 1.0]])), ("line 8", "cov_mm2")),
    "bad_crc_in_the_middle": LogCase(_bad_crc, ("line 5",)),
    "garbage_line_in_the_middle": LogCase(lambda ls: ls[:4] + [b"garbage\n"] + ls[4:], ("line 5",)),
    "seq_gap": LogCase(_seq_gap, ("line 6",)),
    "start_record_missing": LogCase(lambda ls: ls[1:], ("line 1",)),
    "empty_log": LogCase(raw=b"", needles=("log.jsonl",)),
    "binary_log": LogCase(raw=bytes(range(256)), needles=("log.jsonl",)),
}


@pytest.mark.system
def test_log_table_size():
    assert len(LOG_CASES) >= 15


@pytest.mark.system
@pytest.mark.parametrize("name", sorted(LOG_CASES))
def test_hostile_log_resume_refused_before_anything_moves(name, base, tmp_path, capsys):
    case = LOG_CASES[name]
    lines = [bytes(b) for b in base["lines"]]
    run = _interrupted(tmp_path, base, [case.raw] if case.raw is not None else case.edit(lines))
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "run", base["config"], "--resume", run)
    assert_one_line(code, out, err, 2, "log.jsonl", *case.needles)
    assert snapshot(tmp_path) == before                  # not even a resume event was appended


@pytest.mark.parametrize("name", ["xyz_1e300", "xyz_strings", "xyz_missing", "bad_crc_in_the_middle",
                                  "seq_gap", "empty_log", "q_read_1000_deg"])
@pytest.mark.system
def test_hostile_log_reprocess(name, base, tmp_path, capsys):
    case = LOG_CASES[name]
    lines = [bytes(b) for b in base["lines"]]
    run = _interrupted(tmp_path, base, [case.raw] if case.raw is not None else case.edit(lines))
    before = snapshot(tmp_path)
    code, out, err = cli(capsys, "reprocess", run, "--config", base["config"], "--out", tmp_path / "out")
    assert_one_line(code, out, err, 2, "log.jsonl")
    assert snapshot(tmp_path) == before


@pytest.mark.system
def test_reprocess_of_an_interrupted_run_says_what_is_missing(base, tmp_path, capsys):
    run = _interrupted(tmp_path, base)
    code, out, err = cli(capsys, "reprocess", run, "--config", base["config"], "--out", tmp_path / "out")
    assert code == 2 and "calib rows" in err                 # 12 points are too few to calibrate ...
    full = [bytes(b) for b in (base["run"] / "log.jsonl").read_bytes().splitlines(keepends=True)]
    n_test = sum(json.loads(b)["data"].get("set") == "test" for b in full if json.loads(b)["kind"] == "point")
    cut = [b for b in full if json.loads(b)["kind"] != "stop"]
    keep = [b for b in cut if json.loads(b)["kind"] != "point" or json.loads(b)["data"]["set"] != "test"]
    keep += [b for b in cut if json.loads(b)["kind"] == "point" and json.loads(b)["data"]["set"] == "test"][:5]
    seqs = [encode_record(json.loads(b)["kind"], i, json.loads(b)["data"]) for i, b in enumerate(keep)]
    shutil.rmtree(run)
    run = _interrupted(tmp_path, base, seqs)
    code, out, err = cli(capsys, "reprocess", run, "--config", base["config"], "--out", tmp_path / "out")
    assert code == 0, err                                     # ... this one calibrates, and says the test set is short
    assert f"only 5 of {n_test} planned test points were measured" in out


# ----------------------------------------------------------------------------------------------- I/O faults

@dataclass(frozen=True)
class IOCase:
    argv: Callable[[dict, Path], list]
    code: int
    needles: tuple[str, ...] = ()


IO_CASES: dict[str, IOCase] = {
    "config_missing": IOCase(lambda b, t: ["validate", t / "nope.yaml"], 2, ("nope.yaml", "not found")),
    "config_is_directory": IOCase(lambda b, t: ["validate", t], 2, ("directory",)),
    "resume_missing_dir": IOCase(lambda b, t: ["run", b["config"], "--resume", t / "nope"], 2, ("nope",)),
    "resume_dir_without_log": IOCase(lambda b, t: ["run", b["config"], "--resume", t], 2, ("log.jsonl",)),
    "plan_csv_into_missing_dir": IOCase(lambda b, t: ["plan", b["config"], "--csv", t / "nope" / "plan.csv"], 2,
                                        ("nope/plan.csv", "does not exist")),
    "reprocess_missing_source": IOCase(lambda b, t: ["reprocess", t / "nope.csv", "--config", b["config"],
                                                     "--out", t / "o"], 2, ("nope.csv",)),
    "reprocess_dir_without_log": IOCase(lambda b, t: ["reprocess", t, "--config", b["config"], "--out", t / "o"], 2,
                                        ("log.jsonl",)),
    "reprocess_out_is_a_file": IOCase(lambda b, t: ["reprocess", b["run"], "--config", b["config"],
                                                    "--out", b["config"]], 2, (str(Path("irb2600-small.yaml")),)),
    "correct_targets_missing": IOCase(lambda b, t: ["correct", "--config", b["config"], "--model",
                                                    b["run"] / "model.json", "--targets", t / "nope.csv",
                                                    "--out", t / "o"], 2, ("nope.csv",)),
    "correct_model_missing": IOCase(lambda b, t: ["correct", "--config", b["config"], "--model", t / "nope.json",
                                                  "--targets", t / "x.csv", "--out", t / "o"], 2, ("nope.json",)),
    "verify_missing_run": IOCase(lambda b, t: ["verify", t / "nope"], 2, ("nope",)),
    "diagnose_missing_source": IOCase(lambda b, t: ["diagnose", t / "nope", "--config", b["config"]], 2,
                                      ("nope",)),
}


@pytest.mark.system
@pytest.mark.parametrize("name", sorted(IO_CASES))
def test_missing_paths(name, base, tmp_path, capsys):
    case = IO_CASES[name]
    before = snapshot(tmp_path, base["run"])
    code, out, err = cli(capsys, *case.argv(base, tmp_path))
    assert_one_line(code, out, err, case.code, *case.needles)
    assert snapshot(tmp_path, base["run"]) == before


@pytest.mark.system
def test_read_only_output_dir(base, tmp_path, capsys, monkeypatch):
    """The output directory is on a read-only file system (simulated: we run as root in CI containers)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real_open, real_mkdir = os.open, os.mkdir

    def refuse(path):
        if str(path).startswith(str(ro)):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))

    monkeypatch.setattr(os, "open", lambda path, *a, **k: (refuse(path), real_open(path, *a, **k))[1])
    monkeypatch.setattr(os, "mkdir", lambda path, *a, **k: (refuse(path), real_mkdir(path, *a, **k))[1])
    code, out, err = cli(capsys, "reprocess", base["run"], "--config", base["config"], "--out", ro / "out")
    assert_one_line(code, out, err, 2, str(ro / "out"), "Read-only file system")
    assert list(ro.iterdir()) == []


@pytest.mark.system
def test_disk_full_during_reprocess(base, tmp_path, capsys, monkeypatch):
    def full(fd, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "write", full)
    out_dir = tmp_path / "out"
    code, out, err = cli(capsys, "reprocess", base["run"], "--config", base["config"], "--out", out_dir)
    monkeypatch.undo()
    assert_one_line(code, out, err, 1, "No space left on device")
    assert not out_dir.exists() or list(out_dir.iterdir()) == []      # no partial report/model, no temp file


@pytest.mark.system
def test_disk_full_during_run_keeps_the_log_intact(base, tmp_path, capsys, monkeypatch):
    from campaign.run import log_reader as runlog

    real = runlog.os.write
    calls = {"n": 0}

    def fills_up(fd, data):
        calls["n"] += 1
        if calls["n"] > 6:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data)

    monkeypatch.setattr(os, "write", fills_up)
    run = tmp_path / "run"
    code, out, err = cli(capsys, "run", base["config"], "--out", run)
    monkeypatch.undo()
    assert_one_line(code, out, err, 1, "No space left on device")
    contents = read_log(run)                                      # what was written is intact and readable
    assert 1 <= len(contents.points) <= 6


@pytest.mark.system
def test_internal_error_writes_a_crash_report(base, tmp_path, capsys, monkeypatch):
    import campaign.plan.build

    def boom(*a, **k):
        raise RuntimeError("simulated internal bug")

    monkeypatch.setattr(campaign.plan.build, "build_plan", boom)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    code, out, err = cli(capsys, "plan", base["config"])
    line = assert_one_line(code, out, err, 3, "internal error", "RuntimeError", "crash report")
    report = Path(line.rsplit("crash report ", 1)[1])
    text = report.read_text()
    assert report.parent == tmp_path and "Traceback" in text and "simulated internal bug" in text
    assert "command: campaign plan" in text and "numpy" in text


# ------------------------------------------------------------------------------- real entry point (subprocess)

def _campaign(*argv, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "campaign", *map(str, argv)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ, PYTHONHASHSEED="0"), **kw)


@pytest.mark.system
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP", "SIGINT"])
def test_signal_stops_the_run_closes_the_log_and_prints_the_resume_command(sig, tmp_path):
    cfg = small_config(tmp_path, **{"simulation.motion_time_s": 0.02})
    run = tmp_path / "run"
    proc = _campaign("run", cfg, "--out", run)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if (run / "log.jsonl").exists() and len(read_log(run).points) >= 3:
            break
        time.sleep(0.01)
    proc.send_signal(getattr(signal, sig))
    out, err = proc.communicate(timeout=60)
    err = err.decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"--resume {run}" in err
    stop = read_log(run).stops[-1]
    assert stop["exit_status"] == "abort"
    assert stop["reason"] == (f"terminated by {sig}" if sig != "SIGINT" else "interrupted by the operator (Ctrl-C)")


@pytest.mark.system
def test_real_entry_point_alias_bomb_and_file_size_limit(tmp_path):
    bomb = tmp_path / "bomb.yaml"
    from tests.campaign.config.test_hostile_configs import BOMB

    bomb.write_bytes(BOMB)
    proc = _campaign("validate", bomb)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and b"alias" in err and len(err.strip().splitlines()) == 1

    def limit():                                   # a disk that fills up after 20 kB per file
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    cfg = small_config(tmp_path)
    proc = _campaign("run", cfg, "--out", tmp_path / "run", preexec_fn=limit)
    out, err = proc.communicate(timeout=120)
    err = err.decode()
    assert proc.returncode == 1, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and "too large" in err.lower(), err
    read_log(tmp_path / "run")                     # the records written before the limit are intact


# ----------------------------------------------------------------------------------------------- correct

def _targets(tmp: Path, rows: list[str]) -> Path:
    path = tmp / "targets.csv"
    path.write_text("target_id,x,y,z\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.system
def test_correct_all_rejected_exits_1_with_the_reasons(base, tmp_path, capsys):
    targets = _targets(tmp_path, ["FAR1,3000,0,1000", "FAR2,0,3500,0"])
    out_dir = tmp_path / "out"
    code, out, err = cli(capsys, "correct", "--config", base["config"], "--model", base["run"] / "model.json",
                         "--targets", targets, "--out", out_dir)
    assert_one_line(code, out, err, 1, "nothing to write", "all 2 targets rejected", "FAR1")
    assert "2 of 2 targets rejected" in out and "FAR2: unreachable" in out
    assert sorted(p.name for p in out_dir.iterdir()) == [MARKER, "rejected.csv"]
    assert (out_dir / "rejected.csv").read_text().count("unreachable") == 2


@pytest.mark.system
def test_correct_model_of_another_robot_exits_2(base, tmp_path, capsys):
    other = small_config(tmp_path, "irb4600")
    targets = _targets(tmp_path, ["A,900,0,1000"])
    code, out, err = cli(capsys, "correct", "--config", other, "--model", base["run"] / "model.json",
                         "--targets", targets, "--out", tmp_path / "out")
    assert_one_line(code, out, err, 2, "model.json", "beyond physical bounds")
    assert not (tmp_path / "out").exists()


@pytest.mark.system
def test_correct_long_id_is_rejected_with_its_reason_and_only_the_controllers_formats(base, tmp_path, capsys):
    long_id = "L" * 90
    targets = _targets(tmp_path, ["A,900,0,1000", f"{long_id},1000,100,900"])
    out_dir = tmp_path / "out"
    code, out, err = cli(capsys, "correct", "--config", base["config"], "--model", base["run"] / "model.json",
                         "--targets", targets, "--out", out_dir)
    assert code == 0, err
    assert "1 of 2 targets rejected" in out and "at most 80 characters" in out
    assert sorted(p.name for p in out_dir.iterdir()) == [MARKER, "CalTargets.mod", "rejected.csv", "targets.csv"]  # ABB
    header = (out_dir / "targets.csv").read_text().splitlines()[0]
    assert "predicted_std_mm" not in header            # IDW model: no all-nan column
