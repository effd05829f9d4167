"""The README's main job and closed-loop verification on the mock cell, with repeated closed-loop passes.

Prints the wall time of `campaign run configs/irb2600.yaml`, then runs `campaign verify` with 8 closed-loop
passes (config copy with correction.closed_loop_iterations = 8) and prints RMS / noise floor per pass: with
~94 test points a single pass scatters by a few per cent, which is why the pooled figure is the estimate.
"""
import json
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from campaign.cli import main as campaign  # noqa: E402
from campaign.correct.verify_report import VerifyReport  # noqa: E402


def main(passes: int = 8) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        doc = yaml.safe_load((ROOT / "configs/irb2600.yaml").read_text())
        doc["correction"]["closed_loop_iterations"] = passes
        cfg = Path(tmp) / "irb2600.yaml"
        cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
        run = Path(tmp) / "run"
        t0 = time.perf_counter()
        assert campaign(["run", str(ROOT / "configs/irb2600.yaml"), "--out", str(Path(tmp) / "main")]) == 0
        print(f"campaign run configs/irb2600.yaml (mock cell, plan + measure + calibrate + report): "
              f"{time.perf_counter() - t0:.1f} s wall time")
        assert campaign(["run", str(cfg), "--out", str(run)]) == 0
        assert campaign(["verify", str(run)]) == 0
        report = VerifyReport.from_dict(json.loads(next(run.glob("verify-*/verify.json")).read_text()))
    floor = report.noise_floor_mm
    ratios = {k: v.rms_mm / floor for k, v in report.stages.items()}
    print("RMS / noise floor: " + ", ".join(f"{k} {r:.2f}" for k, r in ratios.items()))
    loops = [r for k, r in ratios.items() if k.startswith("closed loop")]
    print(f"{len(loops)} closed-loop passes: single-pass ratio {min(loops):.2f} .. {max(loops):.2f}")


if __name__ == "__main__":
    main()
