"""Kill study of ``campaign run`` (issue 36): SIGKILL at seeded random instants over whole runs of a small mock
cell (set-up, plan, measuring, calibration, figures, report), then ``--resume`` or, where resume refuses,
``--overwrite``. Prints, per trial and in total, where the kill landed, how the directory recovered, and the
points lost or duplicated; exits 1 when any trial failed, lost or duplicated a point, or left a torn file.

    OPENBLAS_NUM_THREADS=1 python3 bench/bench_kill.py [--kills 100] [--seed 36] [--keep DIR]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tests.campaign.kill_study import study, summary  # noqa: E402
from tests.campaign.helpers import small_config  # noqa: E402
from tests.campaign.test_hostile_harms import few_point_doc  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=100)
    parser.add_argument("--seed", type=int, default=36)
    parser.add_argument("--keep", type=Path, help="keep the runs in this directory")
    parser.add_argument("--small", action="store_true",
                        help="the tests' 21-point cell (default: the 90-point reduced demo cell, whose measuring "
                             "lasts longer, so that more kills land while it measures)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        if args.small:
            doc = few_point_doc()
            doc["output"] = {"dir": str(work / "runs")}
            cfg = work / "small.yaml"
            cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
        else:
            cfg = small_config(work)
        trials = study(cfg, work, args.kills, args.seed)
    for k, t in enumerate(trials):
        print(f"{k:3d} kill at {t.delay_s:6.2f} s  aimed {t.aim:16s} landed {t.phase:18s} recovery {t.recovery:9s} exit {t.exit_code}  "
              f"lost {t.lost} duplicated {t.duplicated}" + (f"  torn {', '.join(t.torn_files)}" if t.torn_files else ""))
    s = summary(trials)
    print(f"{s['kills']} kills: phases {s['phases']}; recoveries {s['recoveries']}; failed {s['failed']}, "
          f"lost {s['lost']}, duplicated {s['duplicated']}, torn {s['torn']}")
    return 1 if s["failed"] or s["lost"] or s["duplicated"] or s["torn"] else 0


if __name__ == "__main__":
    sys.exit(main())
