"""Where one ``campaign`` command's resident memory peaks: its RSS sampled every 0.1 s with the innermost project
functions running at that instant, the highest RSS per stage printed (the process's peak first).

A sampling thread reads ``/proc/self/statm`` and the main thread's stack (``campaign/``, ``robocal/`` and
``drivers/`` frames, innermost three); the table is printed before the command leaves (through ``os._exit``, like
``profile_command.py``). A stage that holds its memory for less than 0.1 s may be missed; the sampler's own cost
is a few MiB. Figures are the process's RSS, not the allocations of the stage alone: a stage's row shows what the
process held while it ran.

    python bench/memory_stages.py [--top N] -- diagnose data.csv --config configs/irb2600.yaml --json out.json
"""
from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PAGE_MIB = os.sysconf("SC_PAGE_SIZE") / 2**20
ROOMS = tuple(f"{os.sep}{r}{os.sep}" for r in ("campaign", "robocal", "drivers"))


def rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE_MIB


def stage(thread_id: int) -> str:
    """The innermost three project functions on a thread's stack ('module.py:function < ...')."""
    frame, names = sys._current_frames().get(thread_id), []
    while frame is not None and len(names) < 3:
        path = frame.f_code.co_filename
        if any(r in path for r in ROOMS):
            names.append(f"{Path(path).parent.name}/{Path(path).name}:{frame.f_code.co_name}")
        frame = frame.f_back
    return " < ".join(names) or "(outside the project)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=15, help="stages printed")
    own, argv = (sys.argv[1:sys.argv.index("--")], sys.argv[sys.argv.index("--") + 1:]) if "--" in sys.argv else (
        sys.argv[1:], [])
    a = ap.parse_args(own)
    if not argv:
        ap.error("give the campaign command after --")
    from campaign.cli.entry import main as campaign_main

    peaks: dict[str, float] = {}
    main_id, done, leave, t0 = threading.get_ident(), threading.Event(), os._exit, time.process_time()

    def sample() -> None:
        while not done.wait(0.1):
            where, mib = stage(main_id), rss_mib()
            peaks[where] = max(mib, peaks.get(where, 0.0))

    def report_and_leave(code: int) -> None:
        done.set()
        peak = max(peaks.values(), default=0.0)
        print(f"exit {code}, CPU {time.process_time() - t0:.1f} s, peak RSS sampled {peak:.0f} MiB; highest RSS per "
              "stage (innermost project functions):", file=sys.stderr)
        for where, mib in sorted(peaks.items(), key=lambda kv: -kv[1])[:a.top]:
            print(f"{mib:8.0f} MiB  {where}", file=sys.stderr)
        sys.stderr.flush()
        leave(code)

    threading.Thread(target=sample, daemon=True).start()
    os._exit = report_and_leave
    report_and_leave(campaign_main(argv))


if __name__ == "__main__":
    main()
