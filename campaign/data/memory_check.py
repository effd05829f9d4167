"""Will a dataset fit in this machine's memory? One early check, from the number of rows, before anything is read.

A command's peak memory grows with the rows of its data: ``campaign reprocess`` and ``diagnose`` by
``CALIBRATE.row_bytes`` per row (the dataset, the per-row arrays of the fits and predictions, the per-point
report) on top of ``CALIBRATE.base_bytes``, and, up to ``CV_MAX_ROWS`` rows, by ``CALIBRATE.capped_row_bytes`` more
per row (the cross-validated choices work on at most that many rows); ``campaign select`` by its own ``SELECT``.
The figures are the line through the peaks ``bench/bench_scale.py`` measured at 20 000, 200 000 and
1 000 000 rows (docs/results.md; for ``CALIBRATE`` the larger of reprocess and diagnose), each constant
raised by 15 % and rounded up. Where the need exceeds what this
process may still use (the memory available on the machine, the address-space limit ``ulimit -v`` and the
control group's limit, whichever is least), the command stops with one line saying how many rows fit and what to
do, instead of running out of memory part-way.
"""
from __future__ import annotations

import os
import resource
from dataclasses import dataclass
from pathlib import Path

from campaign.errors import DataError
from robocal.effects.cv import CV_MAX_ROWS

MIB = 1 << 20


@dataclass(frozen=True)
class Need:
    """Peak memory of a command (bytes) as a function of its rows: ``base_bytes + row_bytes * rows +
    capped_row_bytes * min(rows, CV_MAX_ROWS)``; ``advice`` says what to do when the data does not fit."""
    base_bytes: int
    row_bytes: int
    capped_row_bytes: int
    advice: str

    def bytes(self, rows: int) -> int:
        return self.base_bytes + self.row_bytes * rows + self.capped_row_bytes * min(rows, CV_MAX_ROWS)

    def rows_within(self, budget: int) -> int:
        """The most rows whose need stays within ``budget`` bytes (0 when none)."""
        free = budget - self.base_bytes
        if free <= 0:
            return 0
        capped = min(CV_MAX_ROWS, free // (self.row_bytes + self.capped_row_bytes))
        if capped < CV_MAX_ROWS:
            return int(capped)
        return int(CV_MAX_ROWS + (budget - self.bytes(CV_MAX_ROWS)) // self.row_bytes)


# measured peaks (MiB) at 20k / 200k / 1M rows: diagnose 410 / 929 / 1651 (reprocess 325 / 676 / 1463): the line
# 352 MiB + 946 B/row + 2077 B/row up to CV_MAX_ROWS; select 203 / 873 / 1303: 129 MiB + 564 + 3339 B/row; + 15 %
CALIBRATE = Need(410 * MIB, 1100, 2400, "calibrate a subset (`campaign select DATA --points N --out SUBSET.csv` keeps N "
                 "calibration rows and every test and check row) or use a machine with more memory")
SELECT = Need(150 * MIB, 650, 3850, "split the data into parts of at most that many rows, or use a machine with more "
              "memory")


def count_rows(source: str | os.PathLike) -> int:
    """Lines of a CSV, or of a run directory's log.jsonl (an upper bound of its rows), counted in 16 MiB reads."""
    path = Path(source)
    path = path / "log.jsonl" if path.is_dir() else path
    lines = 0
    try:
        with open(path, "rb") as fh:
            while chunk := fh.read(16 * MIB):
                lines += chunk.count(b"\n")
    except OSError:
        return 0                                    # the reader says what is wrong with the path
    return lines


def _proc_kib(path: str, key: str) -> int | None:
    """The KiB value of ``key`` in a /proc file of ``key: value kB`` lines (None when absent or unreadable)."""
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_free() -> int | None:
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
    except (OSError, ValueError):
        return None


def available_bytes() -> tuple[int, str] | None:
    """(bytes this process may still allocate, what limits it) or None when nothing is known: the least of the
    machine's available memory, the address-space limit (``ulimit -v``) less what the process already maps, and
    the control group's memory limit less its use."""
    out = []
    avail = _proc_kib("/proc/meminfo", "MemAvailable")
    if avail is not None:
        out.append((avail * 1024, "available memory"))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    mapped = _proc_kib("/proc/self/status", "VmSize")
    if soft != resource.RLIM_INFINITY and mapped is not None:
        out.append((soft - mapped * 1024, "the address-space limit (ulimit -v)"))
    cg = _cgroup_free()
    if cg is not None:
        out.append((cg, "the control group's memory limit"))
    return min(out) if out else None


def check_memory(source: str | os.PathLike, need: Need = CALIBRATE) -> None:
    """DataError (one line) when the rows of ``source`` need more memory than this process may still use."""
    rows = count_rows(source)
    have = available_bytes()
    if have is None or need.bytes(rows) <= have[0]:
        return
    budget, what = have
    fit = need.rows_within(budget)
    raise DataError(str(source), f"{rows} rows need about {_gib(need.bytes(rows))} of memory, {what} leaves "
                                 f"{_gib(max(budget, 0))}: at most {fit} rows fit; {need.advice}")


def _gib(n: int) -> str:
    return f"{n / (1 << 30):.1f} GiB"
