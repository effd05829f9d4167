"""Durable writes against a hostile neighbour (issue 36): temporary files are new files with random names, opened
with O_EXCL | O_NOFOLLOW; an output that is a link, a device or a FIFO is never replaced; stale temporaries of
killed writers (a PID that no longer runs) are recognised and removed by the next successful write."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

import campaign.io.durable as durable
from campaign.errors import DataError, Terminated
from campaign.io.durable import atomic_write, create_temp, stale_temp

pytestmark = pytest.mark.unit


def dead_pid() -> int:
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True, check=True).stdout)


def test_a_planted_link_at_the_drawn_temporary_name_is_not_opened(tmp_path, monkeypatch):
    victim = tmp_path / "victim"
    victim.write_text("precious")
    tokens = iter(["aaaaaaaaaaaa", "bbbbbbbbbbbb"])
    monkeypatch.setattr(durable.secrets, "token_hex", lambda n: next(tokens))
    out = tmp_path / "out.json"
    os.symlink(victim, tmp_path / f".out.json.{os.getpid()}.aaaaaaaaaaaa.tmp")
    atomic_write(out, b"new")
    assert victim.read_text() == "precious" and out.read_text() == "new"
    assert (tmp_path / f".out.json.{os.getpid()}.aaaaaaaaaaaa.tmp").is_symlink()     # left as it was


def test_an_output_that_is_a_link_or_a_fifo_is_never_replaced(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious")
    link, fifo = tmp_path / "link.json", tmp_path / "fifo.json"
    os.symlink(victim, link)
    os.mkfifo(fifo)
    for path in (link, fifo):
        with pytest.raises(DataError, match="not a regular file"):
            atomic_write(path, b"new")
    assert victim.read_text() == "precious" and link.is_symlink() and not fifo.is_file()
    assert not list(tmp_path.glob(".*.tmp"))


def test_stale_temporaries_are_those_of_a_process_that_is_gone(tmp_path):
    gone = dead_pid()
    stale = tmp_path / f".model.json.{gone}.tmp"
    stale_new = tmp_path / f".model.json.{gone}.0f0f0f.tmp"
    mine = tmp_path / f".model.json.{os.getpid()}.tmp"
    parent = tmp_path / f".model.json.{os.getppid()}.tmp"          # a process that runs
    for p in (stale, stale_new, mine, parent):
        p.write_text("x")
    link = tmp_path / f".report.json.{gone}.tmp"
    os.symlink(tmp_path / "elsewhere", link)
    assert stale_temp(stale) and stale_temp(stale_new)
    assert not stale_temp(mine) and not stale_temp(parent) and not stale_temp(link)
    assert not stale_temp(tmp_path / "notes.tmp")
    atomic_write(tmp_path / "model.json", b"{}")
    assert not stale.exists() and not stale_new.exists() and mine.exists() and parent.exists() and link.is_symlink()


def test_create_temp_names_are_random_hidden_and_beside_the_target(tmp_path):
    names = set()
    for _ in range(5):
        fd, tmp = create_temp(tmp_path / "a.csv")
        os.close(fd)
        names.add(tmp.name)
        assert tmp.parent == tmp_path and tmp.name.startswith(f".a.csv.{os.getpid()}.") and tmp.suffix == ".tmp"
    assert len(names) == 5


def _no_hard_links(monkeypatch):
    def refuse(src, dst, *args, **kwargs):
        raise OSError(1, "Operation not permitted")         # what FAT and some network mounts answer
    monkeypatch.setattr(durable.os, "link", refuse)


@pytest.mark.parametrize("links", [True, False], ids=["hard-link", "no-hard-links"])
def test_create_new_makes_the_file_whole_and_never_replaces_one(tmp_path, monkeypatch, links):
    if not links:
        _no_hard_links(monkeypatch)
    path = tmp_path / "log.jsonl"
    durable.create_new(path, b"first\n")
    assert path.read_bytes() == b"first\n"
    with pytest.raises(FileExistsError):
        durable.create_new(path, b"second\n")
    assert path.read_bytes() == b"first\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.jsonl"]      # no temporary file left


def test_a_run_log_and_a_directory_marker_are_created_where_hard_links_are_unsupported(tmp_path, monkeypatch):
    from campaign.run.log_reader import RunLogExistsError
    from campaign.run.log_writer import RunLog
    from campaign.run.output_dirs import Claim, read_marker, release_locks

    _no_hard_links(monkeypatch)
    log = RunLog.create(tmp_path / "run", {"created_utc": "2026-11-29T00:00:00+00:00"})
    log.close("success")
    assert (tmp_path / "run" / "log.jsonl").read_bytes().startswith(b'{"')
    with pytest.raises(RunLogExistsError):
        RunLog.create(tmp_path / "run", {"created_utc": "2026-11-29T00:00:00+00:00"})
    try:
        Claim(tmp_path / "out", "reprocess", source="data.csv").take()
    finally:
        release_locks()
    assert read_marker(tmp_path / "out") == {"kind": "reprocess", "source": "data.csv"}
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".campaign-owner.json"]


@pytest.mark.parametrize("write", ["atomic_write", "create_new"])
def test_a_signal_between_the_temporary_files_creation_and_its_try_leaves_nothing(tmp_path, monkeypatch, write):
    """The signal's exception raised as ``os.open`` returns the temporary file (before its name reaches the caller,
    where SIGTERM once left ``.model.json.PID.X.tmp`` behind): no temporary is left, the output is absent, and the
    exception goes on."""
    real_open = os.open

    def open_then_signal(path, flags, mode=0o777):
        fd = real_open(path, flags, mode)
        os.close(fd)
        raise Terminated("SIGTERM")

    monkeypatch.setattr(durable.os, "open", open_then_signal)
    out = tmp_path / "model.json"
    with pytest.raises(Terminated):
        getattr(durable, write)(out, b"{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
