"""Tests of the durable append-only run log (campaign/run/log_reader.py)."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
import zlib
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from campaign.errors import DataError
from campaign.run.log_reader import (LOG_NAME, RunLogError, RunLogExistsError, completed_point_ids, encode_record,
                                     read_log)
from campaign.run.log_writer import RunLog


REPO = Path(__file__).resolve().parents[3]

START = {
    "config_sha256": "ab" * 32,
    "plan_sha256": "cd" * 32,
    "config": {"name": "irb2600", "robot": {"model": "IRB 2600"}},
    "created_utc": "2026-01-01T00:00:00Z",
    "software_version": "0.1.0",
    "units": {"q": "deg", "p": "mm", "t": "s"},
}


def point(i: int, kind: str = "plan") -> dict:
    """A measurement record like the campaign writes (deterministic values)."""
    return {
        "point_id": f"P{i:03d}",
        "set": "calib" if i % 3 else "test",
        "kind": kind,
        "q_cmd_deg": [10.0 + i, -20.5, 30.25, 0.0, 45.0, -90.0],
        "q_read_deg": [10.0 + i + 1e-4, -20.5, 30.25, 0.0, 45.0, -90.0],
        "p_tracker_mm": [1500.125 + i, -250.5, 1200.0625],
        "sigma_mm": 0.012,
        "n_samples": 5,
        "spread_mm": 0.004,
        "t_start_s": 10.0 * i,
        "t_end_s": 10.0 * i + 2.5,
        "temperatures": {"temp_c": 21.5},
        "payload_kg": 0.0,
        "retries": 0,
    }


def check_record_line(raw: bytes, seq: int) -> dict:
    """Independent check of one log line: keys, consecutive seq, CRC."""
    rec = json.loads(raw)
    assert set(rec) == {"kind", "seq", "data", "crc"}
    assert rec["seq"] == seq
    canonical = json.dumps(
        {"kind": rec["kind"], "seq": rec["seq"], "data": rec["data"]},
        sort_keys=True,
        separators=(",", ":"),
        allow_nan=False,
    )
    assert rec["crc"] == format(zlib.crc32(canonical.encode()) & 0xFFFFFFFF, "08x")
    return rec


def make_log(run_dir: Path, n_points: int = 5, status: str | None = "success") -> Path:
    log = RunLog.create(run_dir, START)
    for i in range(n_points):
        log.append_point(point(i))
    if status:
        log.close(status, "done")
    else:
        del log  # as after a crash: no stop record, descriptor released
    return run_dir / LOG_NAME


# ---------------------------------------------------------------- round trip


@pytest.mark.unit
def test_round_trip(tmp_path):
    run = tmp_path / "run"
    with RunLog.create(run, START) as log:
        assert log.next_seq == 1
        seqs = [log.append_point(point(i)) for i in range(4)]
        log.append_event({"type": "pause", "reason": "operator"})
        log.append_point({**point(9, "check"), "q_cmd_deg": np.arange(6) * 0.5, "n_samples": np.int64(5)})
        log.close("success", "all done")
        log.close("fail", "ignored: second close is a no-op")
    assert seqs == [1, 2, 3, 4]
    c = read_log(run / LOG_NAME)
    assert c.start == START
    assert [p["point_id"] for p in c.points] == ["P000", "P001", "P002", "P003", "P009"]
    assert c.points[0] == point(0)
    assert c.points[-1]["q_cmd_deg"] == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
    assert c.events == [{"type": "pause", "reason": "operator"}]
    closed = datetime.fromisoformat(c.stops[0].pop("closed_utc"))      # the wall-clock time the log closed
    assert closed.tzinfo is not None and abs((datetime.now(timezone.utc) - closed).total_seconds()) < 600
    assert c.stops == [{"exit_status": "success", "reason": "all done", "n_points": 5}]
    assert not c.torn_tail
    blob = (run / LOG_NAME).read_bytes()
    assert c.n_good_bytes == len(blob) and c.n_records == 8
    lines = blob.split(b"\n")
    assert lines[-1] == b""
    kinds = [check_record_line(raw, seq)["kind"] for seq, raw in enumerate(lines[:-1])]
    assert kinds == ["start"] + ["point"] * 4 + ["event", "point", "stop"]
    assert completed_point_ids(c) == {"P000", "P001", "P002", "P003", "P009"}
    assert read_log(run).n_records == 8  # a run directory is accepted too


@pytest.mark.unit
def test_create_refuses_existing_log(tmp_path):
    make_log(tmp_path)
    with pytest.raises(RunLogExistsError) as info:
        RunLog.create(tmp_path, START)
    assert isinstance(info.value, FileExistsError)
    assert isinstance(info.value, DataError)
    assert str(tmp_path / LOG_NAME) in str(info.value)
    assert not [p for p in tmp_path.iterdir() if p.name != LOG_NAME]  # no temp file left


@pytest.mark.unit
def test_closed_log_refuses_appends(tmp_path):
    log = RunLog.create(tmp_path, START)
    log.close("abort", "e-stop")
    assert log.closed
    with pytest.raises(RunLogError):
        log.append_point(point(0))
    assert read_log(tmp_path).stops[0]["exit_status"] == "abort"


@pytest.mark.unit
def test_bad_arguments(tmp_path):
    log = RunLog.create(tmp_path, START)
    size = (tmp_path / LOG_NAME).stat().st_size
    with pytest.raises(RunLogError, match="not storable"):
        log.append_point({**point(0), "p_tracker_mm": [float("nan"), 0.0, 0.0]})
    with pytest.raises(TypeError):
        log.append_event({"reason": "no type"})
    with pytest.raises(ValueError):
        log.close("weird")
    assert (tmp_path / LOG_NAME).stat().st_size == size  # nothing written
    assert log.append_point(point(0)) == 1  # still usable
    log.close()


@pytest.mark.unit
def test_context_manager_records_failure(tmp_path):
    with pytest.raises(RuntimeError):
        with RunLog.create(tmp_path, START) as log:
            log.append_point(point(0))
            raise RuntimeError("tracker lost the beam")
    stop = read_log(tmp_path).stops[-1]
    assert stop.pop("closed_utc")
    assert stop == {"exit_status": "fail", "reason": "RuntimeError: tracker lost the beam", "n_points": 1}


@pytest.mark.unit
def test_second_writer_is_locked_out(tmp_path):
    log = RunLog.create(tmp_path, START)
    with pytest.raises(RunLogError, match="in use"):
        RunLog.open_for_resume(tmp_path)
    log.close()
    RunLog.open_for_resume(tmp_path).close("paused", "")


# ---------------------------------------------------------------- corruption


def corrupt_line(path: Path, line_no: int) -> None:
    """Change one digit inside record ``line_no`` (1-based): JSON stays valid, CRC breaks."""
    lines = path.read_bytes().split(b"\n")
    raw = lines[line_no - 1]
    assert raw.count(b'"sigma_mm":0.012') == 1
    lines[line_no - 1] = raw.replace(b'"sigma_mm":0.012', b'"sigma_mm":0.013')
    path.write_bytes(b"\n".join(lines))


@pytest.mark.unit
def test_crc_mismatch_in_middle_is_an_error(tmp_path):
    path = make_log(tmp_path)
    corrupt_line(path, 3)
    before = path.read_bytes()
    with pytest.raises(RunLogError) as info:
        read_log(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: line 3: CRC mismatch") and "\n" not in msg
    with pytest.raises(RunLogError, match="line 3"):
        RunLog.open_for_resume(tmp_path)
    assert path.read_bytes() == before  # resume refused and changed nothing


@pytest.mark.unit
def test_bad_json_in_middle_is_an_error(tmp_path):
    path = make_log(tmp_path)
    lines = path.read_bytes().split(b"\n")
    lines[1] = lines[1][:20]
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(RunLogError, match=r": line 2: not valid JSON"):
        read_log(path)


@pytest.mark.unit
def test_seq_out_of_order_is_an_error_even_last(tmp_path):
    path = make_log(tmp_path, n_points=2, status=None)
    with open(path, "ab") as fh:
        fh.write(encode_record("point", 7, point(7)))
    with pytest.raises(RunLogError, match=r"line 4: seq 7 out of order \(expected 3\)"):
        read_log(path)


@pytest.mark.unit
def test_missing_start_is_an_error(tmp_path):
    (tmp_path / LOG_NAME).write_bytes(b"")
    with pytest.raises(RunLogError, match="no complete start record"):
        read_log(tmp_path)
    (tmp_path / LOG_NAME).write_bytes(encode_record("start", 0, START)[:30])
    with pytest.raises(RunLogError, match="no complete start record"):
        RunLog.open_for_resume(tmp_path)


@pytest.mark.unit
@pytest.mark.parametrize("tail", ["half", "no_newline", "bad_crc_last", "garbage", "zeros"])
def test_torn_tail_ignored_then_truncated(tmp_path, tail):
    path = make_log(tmp_path, n_points=4, status=None)
    good = path.read_bytes()
    line = encode_record("point", 5, point(4))
    torn = {
        "half": line[: len(line) // 2],
        "no_newline": line[:-1],
        "bad_crc_last": line.replace(b"1504.125", b"1504.126"),
        "garbage": b"\x00\xff{not json\n",
        "zeros": b"\x00" * 300,
    }[tail]
    with open(path, "ab") as fh:
        fh.write(torn)
    c = read_log(path)
    assert c.torn_tail and c.n_good_bytes == len(good) and len(c.points) == 4
    assert path.read_bytes() == good + torn  # the reader never writes

    log = RunLog.open_for_resume(tmp_path)
    assert log.contents.torn_tail
    assert log.append_point(point(4)) == 6  # 0 start, 1-4 points, 5 resume event
    log.close("success", "")
    blob = path.read_bytes()
    assert blob.startswith(good)  # no earlier byte changed
    c = read_log(path)
    assert not c.torn_tail and len(c.points) == 5
    assert c.events == [{"type": "resume", "previous_exit": None, "dropped_tail_bytes": len(torn)}]


@pytest.mark.unit
def test_resume_after_stop_continues_seq(tmp_path):
    path = make_log(tmp_path, n_points=3, status="paused")
    before = path.read_bytes()
    with RunLog.open_for_resume(tmp_path) as log:
        assert log.n_points == 3
        assert completed_point_ids(log.contents) == {"P000", "P001", "P002"}
        assert log.append_point(point(3)) == 6
        log.close("success", "")
    blob = path.read_bytes()
    assert blob.startswith(before)
    rows = blob.split(b"\n")[:-1]
    kinds = [check_record_line(r, s)["kind"] for s, r in enumerate(rows)]
    assert kinds[4:] == ["stop", "event", "point", "stop"]
    c = read_log(path)
    assert c.events[0] == {"type": "resume", "previous_exit": "paused", "dropped_tail_bytes": 0}
    assert [s["n_points"] for s in c.stops] == [3, 4]


# ---------------------------------------------------------------- SIGKILL


CHILD = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from campaign.run.log_writer import RunLog
    from campaign.run.log_reader import LOG_NAME

    run, tag = Path(sys.argv[1]), sys.argv[2]
    start = {"config_sha256": "0" * 64, "plan_sha256": "1" * 64, "config": {},
             "created_utc": "2026-01-01T00:00:00Z", "software_version": "test", "units": {}}
    if (run / LOG_NAME).exists():
        log = RunLog.open_for_resume(run)
    else:
        log = RunLog.create(run, start)
    sys.stderr.write("open\\n")  # the log is open: the parent's clock for the kill may start
    sys.stderr.flush()
    i = 0
    while True:
        seq = log.append_point({"point_id": f"{tag}-{i}", "q_cmd_deg": [i * 0.1] * 6,
                                "p_tracker_mm": [1.0, 2.0, 3.0], "pad": "x" * (i % 997)})
        sys.stdout.write(f"{seq}\\n")  # acknowledged: on disk
        sys.stdout.flush()
        i += 1
    """
)


@pytest.mark.system
def test_sigkill_at_random_moments(tmp_path):
    rng = np.random.default_rng(20260101)
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    run = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    good_prefix = b""
    total_points = 0
    for trial in range(12):
        ack_path = tmp_path / f"ack{trial}.txt"
        with open(ack_path, "w") as ack:
            cmd = [sys.executable, str(script), str(run), f"T{trial}"]
            child = subprocess.Popen(cmd, stdout=ack, stderr=subprocess.PIPE, env=env)
            if trial % 3:        # from the open log (start-up under load can outlast 0.4 s); else from the spawn
                assert select.select([child.stderr], [], [], 60)[0] and child.stderr.readline() == b"open\n"
            time.sleep(float(rng.uniform(0.0, 0.4)))
            child.send_signal(signal.SIGKILL)
            child.wait(timeout=10)
            child.stderr.close()
        if not (run / LOG_NAME).exists():
            assert good_prefix == b"" and ack_path.read_text() == ""
            continue  # killed before the log was created
        blob = (run / LOG_NAME).read_bytes()
        assert blob.startswith(good_prefix), f"trial {trial}: earlier bytes changed"
        contents = read_log(run)
        good = blob[: contents.n_good_bytes]
        for seq, raw in enumerate(good.split(b"\n")[:-1]):
            check_record_line(raw, seq)
        acked = [int(s) for s in ack_path.read_text().split("\n")[:-1]]
        if acked:  # every acknowledged record survived
            assert max(acked) < contents.n_records
        total_points = len(contents.points)
        good_prefix = good
    assert total_points > 0, "children never got to append: test is vacuous"
    log = RunLog.open_for_resume(run)
    log.append_point({"point_id": "final", "q_cmd_deg": [0.0] * 6, "p_tracker_mm": [0.0, 0.0, 0.0]})
    log.close("success", "")
    assert (run / LOG_NAME).read_bytes().startswith(good_prefix)
    final = read_log(run)
    assert not final.torn_tail and final.points[-1]["point_id"] == "final"
    assert len({p["point_id"] for p in final.points}) == len(final.points)


@pytest.mark.unit
def test_the_log_writer_and_reader_import_no_numerics():
    """The durable log and its records import the standard library only (no numpy): a process that only writes
    the log starts fast, and the record shape stays independent of the plan and the numerics."""
    code = ("import sys, campaign.run.log_writer, campaign.run.log_reader, campaign.run.log_records; "
            "print(sorted(m for m in ('numpy', 'campaign.plan', 'campaign.data', 'robocal') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
