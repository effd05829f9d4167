"""Every test is either ``unit`` (fast, in-process) or ``system`` (subprocesses, emulators, sockets, whole runs).

A module sets the mark with ``pytestmark`` or on each test. A test with neither, or with both, fails collection,
so ``pytest -m unit`` and ``pytest -m system`` always split the whole suite in two.
"""
from __future__ import annotations

import pytest

KINDS = {"unit", "system"}


@pytest.fixture(autouse=True)
def _unwrapped_output(monkeypatch: pytest.MonkeyPatch) -> None:
    """Command output is not wrapped in tests (``COLUMNS=1000``): tests read phrases and lines of it; the layout at
    a given width (80 columns, ``--width``) is tested in ``tests/campaign/cli/test_columns.py``, which sets its own."""
    monkeypatch.setenv("COLUMNS", "1000")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    bad = [item.nodeid for item in items if len({m.name for m in item.iter_markers()} & KINDS) != 1]
    if bad:
        raise pytest.UsageError("tests need exactly one of the marks unit/system: " + ", ".join(bad[:10])
                                + (f" (+{len(bad) - 10} more)" if len(bad) > 10 else ""))


@pytest.fixture(autouse=True)
def _directory_locks_end_with_the_test():
    """A workflow called in-process holds its directories' locks until its command ends; a test is one command:
    the locks end with it, so a later subprocess of the same test session may use those directories."""
    yield
    import sys
    dirs = sys.modules.get("campaign.run.output_dirs")
    if dirs is not None:
        dirs.release_locks()


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one worker more than the usable cores. About 40 % of the suite's wall time is spent waiting
    (subprocesses, sockets, emulated motion, a browser), so two workers on two cores leave a core idle much of
    the time; a third fills it."""
    import os
    return len(os.sched_getaffinity(0)) + 1


def pytest_ignore_collect(collection_path, config: pytest.Config) -> bool | None:
    """``-m unit`` does not import a test module that cannot hold a unit test (its text never says "unit"): its
    tests would all be deselected, and importing it (emulators, browsers, whole-run helpers) is most of the unit
    tier's collection time. Any other selection collects every module, and the mark check above sees them all."""
    if config.getoption("markexpr", "") != "unit" or collection_path.suffix != ".py" \
            or not collection_path.name.startswith("test_"):
        return None
    return True if "unit" not in collection_path.read_text(encoding="utf-8").lower() else None
