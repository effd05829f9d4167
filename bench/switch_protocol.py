"""The with/without protocol of a change to the default process (shared by ``bench_rank_take.py`` and
``bench_links_form.py``): held-out RMS on issue 32's forms (all rows and rule ``f``'s 50 / 100, the picks made once
with the change off; under ``f`` they do not depend on the model) and the diagnosis self-check, each without and
with the change, and the fixed choice: keep it if the mean ratio (with / without) is at most 1, none exceeds 1.05,
none of the UR5 campaign's exceeds 1.01, and the self-check names no fewer effects right, keeps no fewer controls
clean and accepts no more spuriously."""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from contextlib import nullcontext
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from campaign.calibrate.select_adaptive import adaptive_rows  # noqa: E402
from robocal.diagnose.selfcheck import run_self_check  # noqa: E402
from select_forms import ADAPTIVE_FORMS, ur5_dataset  # noqa: E402
from select_replay import rms_off_on  # noqa: E402

UR5 = "UR5 campaign"


def switch(module, attr: str, off_value, on_value):
    """(off, on): context factories that set ``module.attr`` to the value without and with the change judged."""
    return (lambda: mock.patch.object(module, attr, off_value)), (lambda: mock.patch.object(module, attr, on_value))


def switch_many(module, off_values: dict, on_values: dict):
    """(off, on): context factories that set several attributes of ``module`` at once (``switch`` for one)."""
    return (lambda: mock.patch.multiple(module, **off_values)), (lambda: mock.patch.multiple(module, **on_values))


def line(label, off, on) -> None:
    print(f"  {label:46s} off {off:.4f}  on {on:.4f} mm  ratio {on / off:.3f}", flush=True)


def forms_part(tmp: Path, forms, seeds, off) -> dict:
    """{form: [{size: (off, on)} per seed]} with sizes "all", "50", "100"; ``off()`` the context without the change."""
    out = {}
    for form in forms:
        builds = [(UR5, ur5_dataset())] if form == UR5 else [(f"{form}, seed {s}", ADAPTIVE_FORMS[form](tmp, s))
                                                              for s in seeds]
        out[form] = []
        for label, (ds, cell) in builds:
            with off():
                order = adaptive_rows(ds, cell, 100, rule="f").order
            figs = {}
            for n in (None, 50, 100):
                key = "all" if n is None else str(n)
                figs[key] = rms_off_on(ds, cell, None if n is None else order[:n], off)
                line(f"{label}, {'all rows' if n is None else f'f {n}'}", *figs[key])
            out[form].append(figs)
    return out


def self_check(seeds: int, first_seed: int, off, part: str = "iii") -> dict:
    """The self-check's summary figures without and with the change, on the same fresh trials."""
    out = {}
    for name in ("off", "on"):
        with off() if name == "off" else nullcontext():
            r = run_self_check(seeds, first_seed=first_seed)
        s = r.summary()
        groups = list(s["per_effect"].values()) + list(s["forms"].values())
        out[name] = {"named_right": sum(g["named_right"] for g in groups), "of": sum(g["n"] for g in groups),
                     "controls_clean": s["controls_clean"], "controls": s["controls"],
                     "spurious": s["spurious_acceptances"], "passed": r.passed()}
        print(f"({part}) self-check, change {name}: named right {out[name]['named_right']}/{out[name]['of']}, "
              f"controls clean {s['controls_clean']}/{s['controls']}, spurious acceptances "
              f"{s['spurious_acceptances']}, targets {'pass' if r.passed() else 'MISSED'}", flush=True)
    return out


def judge(figs: dict, checks: dict | None, what: str) -> None:
    """Print the ratios and, with every form and the self-check, whether ``what`` is kept."""
    ratios = {f: [on / off for per in v for off, on in per.values()] for f, v in figs.items()}
    every = np.concatenate([np.asarray(r) for r in ratios.values()])
    print(f"(i) {len(every)} figures: mean ratio {every.mean():.4f}, largest {every.max():.3f}, smallest "
          f"{every.min():.3f}")
    print("issue 32's ratios against all rows, mean over the seeds (worst), off -> on:")
    for form, per in figs.items():
        cells = []
        for n in ("50", "100"):
            r = {k: [p[n][i] / p["all"][i] for p in per] for i, k in enumerate(("off", "on"))}
            cells.append(f"{n}: {np.mean(r['off']):.3f} ({max(r['off']):.3f}) -> {np.mean(r['on']):.3f} "
                         f"({max(r['on']):.3f})")
        print(f"  {form:48s} " + "; ".join(cells))
    if checks is None or len(figs) < 1 + len(ADAPTIVE_FORMS):
        return
    ur5 = max(ratios[UR5]) if UR5 in ratios else np.inf
    off, on = checks["off"], checks["on"]
    sc = (on["named_right"] >= off["named_right"] and on["controls_clean"] >= off["controls_clean"]
          and on["spurious"] <= off["spurious"])
    keep = every.mean() <= 1.0 and every.max() <= 1.05 and ur5 <= 1.01 and sc
    print(f"{what} kept: {keep} (i: mean {every.mean():.4f} <= 1, largest {every.max():.3f} <= 1.05, UR5 largest "
          f"{ur5:.3f} <= 1.01; self-check: named right {on['named_right']} >= {off['named_right']}, controls "
          f"clean {on['controls_clean']} >= {off['controls_clean']}, spurious {on['spurious']} <= {off['spurious']})")


def arguments(doc: str, seeds, first_seed: int, parts) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(seeds))
    ap.add_argument("--parts", nargs="+", default=list(parts), choices=list(parts))
    ap.add_argument("--forms", nargs="+", default=[UR5, *ADAPTIVE_FORMS])
    ap.add_argument("--self-check-seeds", type=int, default=5)
    ap.add_argument("--self-check-first-seed", type=int, default=first_seed)
    ap.add_argument("--json", type=Path, help="write this process's figures, for --combine")
    ap.add_argument("--combine", type=Path, nargs="+", help="judge the figures of several processes' --json")
    return ap


def run(args, off, what: str, checks_part: str, extra=None, on=nullcontext) -> None:
    """The protocol's parts as the arguments ask, inside ``on()`` (the change judged): "i" the forms,
    ``checks_part`` the self-check, ``extra(tmp, parts)`` any other part; or judge the --combine'd figures."""
    with on():
        _run(args, off, what, checks_part, extra)


def _run(args, off, what, checks_part, extra) -> None:
    if args.combine:
        parts = [json.loads(p.read_text()) for p in args.combine]
        figs = {f: [{k: tuple(v) for k, v in per.items()} for per in v] for p in parts for f, v in p["i"].items()}
        judge(figs, next((p["iii"] for p in parts if p.get("iii")), None), what)
        return
    figs, checks = {}, None
    with tempfile.TemporaryDirectory() as tmp:
        if "i" in args.parts:
            figs = forms_part(Path(tmp), args.forms, args.seeds, off)
        if extra is not None:
            extra(Path(tmp), args.parts)
    if checks_part in args.parts:
        checks = self_check(args.self_check_seeds, args.self_check_first_seed, off, checks_part)
    if figs:
        judge(figs, checks, what)
    if args.json:
        args.json.write_text(json.dumps({"i": figs, "iii": checks}))
