"""Profile one ``campaign`` command in this process with cProfile and print its top functions.

``python -m cProfile -m campaign ...`` writes nothing: the command leaves through ``os._exit`` (so that no signal
lands in interpreter teardown), which skips cProfile's own dump. This script enables the profiler around
``campaign.cli.entry.main`` and writes the statistics before the process leaves, however it leaves.

    python bench/profile_command.py OUT.prof [--top N] -- reprocess data.csv --config configs/irb2600.yaml --out DIR
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="where the cProfile statistics are written")
    ap.add_argument("--top", type=int, default=25, help="functions printed by own time and by cumulative time")
    own, argv = (sys.argv[1:sys.argv.index("--")], sys.argv[sys.argv.index("--") + 1:]) if "--" in sys.argv else (
        sys.argv[1:], [])
    a = ap.parse_args(own)
    if not argv:
        ap.error("give the campaign command after --")
    from campaign.cli.entry import main as campaign_main

    prof, leave = cProfile.Profile(), os._exit

    def dump_and_leave(code: int) -> None:
        prof.disable()
        prof.dump_stats(a.out)
        for key in ("tottime", "cumulative"):
            pstats.Stats(str(a.out), stream=sys.stderr).sort_stats(key).print_stats(a.top)
        leave(code)

    os._exit = dump_and_leave
    prof.enable()
    dump_and_leave(campaign_main(argv))


if __name__ == "__main__":
    main()
