"""Swept-path check of a whole plan: conservative advancement (robocal.kinematics.sweep.check_segments) against fixed-step
dense sampling (every segment sampled so no point moves more than 2 mm between samples, the same resolution).
Prints medians, the ratio, and whether both agree on which segments are blocked; also the plan build time with
and without a keep-out box (via search included)."""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from campaign.config.load import load_cell  # noqa: E402
from campaign.plan.build import build_plan  # noqa: E402
from robocal.kinematics.sweep import (Boxes, check_segments, clearances_mm, flange_points_base, lever_arms_mm,  # noqa: E402
                           sample_segments)

ROOT = Path(__file__).resolve().parents[1]
BOX = {"name": "fixture", "min_mm": [700, -300, 700], "max_mm": [1000, 300, 1100]}


def dense(kin, q_a, q_b, pts, boxes, clearance, step_mm=2.0):
    """The alternative: sample every segment at step_mm of the lever-arm bound, test every sample."""
    counts = np.maximum(1, np.ceil(np.abs(q_b - q_a) @ lever_arms_mm(kin, pts) / step_mm)).astype(int)
    blocked = np.zeros(len(q_a), bool)
    for lo in range(0, len(q_a), 32):                      # bounded memory
        q, seg = sample_segments(q_a[lo:lo + 32], q_b[lo:lo + 32], counts[lo:lo + 32])
        d, _ = clearances_mm(flange_points_base(kin, q, pts), boxes.grown(clearance), None)
        np.logical_or.at(blocked, lo + seg, d <= 0)
    return blocked, int(counts.sum())


def timed(fn, repeats):
    out, ts = None, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return out, float(np.median(ts))


def main(repeats: int = 5) -> None:
    doc = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "plain.yaml").write_text(yaml.safe_dump(doc))
        doc["plan"]["keep_out"] = [BOX]
        (Path(tmp) / "box.yaml").write_text(yaml.safe_dump(doc))
        plain, boxed = load_cell(Path(tmp) / "plain.yaml"), load_cell(Path(tmp) / "box.yaml")
    kin = plain.kinematics
    plan, t_plain = timed(lambda: build_plan(plain), 3)
    _, t_box = timed(lambda: build_plan(boxed), 3)
    q = np.radians([p.q_deg for p in plan.points])
    q_a, q_b = q[:-1], q[1:]
    pts = np.array([[0.0, 0.0, 0.0], plain.config.tool.p_flange_smr_mm])
    boxes = Boxes(np.array([BOX["min_mm"]], float), np.array([BOX["max_mm"]], float))
    v, t_ca = timed(lambda: check_segments(kin, q_a, q_b, pts, boxes, None, 25.0), repeats)
    (blocked, n_samples), t_dense = timed(lambda: dense(kin, q_a, q_b, pts, boxes, 25.0), repeats)
    print(f"plan of {len(plan.points)} poses, {len(q_a)} moves, keep-out box {BOX['min_mm']}..{BOX['max_mm']} mm")
    print(f"conservative advancement: median {1e3 * t_ca:.1f} ms, {int(v.blocked.sum())} moves blocked")
    print(f"dense sampling (2 mm, {n_samples} samples): median {1e3 * t_dense:.1f} ms, {int(blocked.sum())} blocked")
    print(f"ratio dense / advancement {t_dense / t_ca:.1f}x; blocked sets agree on "
          f"{int((blocked == v.blocked).sum())}/{len(q_a)} moves (advancement may block more: it is conservative "
          f"below its 2 mm resolution)")
    print(f"build_plan median: no keep-out {t_plain:.2f} s, with the box (skips + via search) {t_box:.2f} s")


if __name__ == "__main__":
    main()
