"""Terminal rendering of a diagnosis and of the withheld-effect self-check (nothing here computes a figure)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table
from rich.text import Text

from campaign.io.terminal_text import clean, keep_words, print_notes
from campaign.report.budget_text import render_budget
from campaign.report.terminal import render_preparation
from robocal.effects.model import EffectChoice

from campaign.io.quantities import floor_mm

if TYPE_CHECKING:
    from robocal.diagnose.selfcheck import SelfCheckResult


# ============================================================================ terminal
def _mm(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def _short_evidence(f: dict) -> str:
    ev = f["evidence"]
    if not ev.get("diagnosable", True):
        return f"cannot tell: {ev.get('reason', '')}"
    if not f["accepted"]:
        return ev.get("reason", "")
    parts = [f"held-out {ev['cv_rms_before_mm']:.3f} -> {ev['cv_rms_after_mm']:.3f} mm "
             f"(t {ev['cv_gain_t']:.1f}, {ev['cv_blocking']}; {100 * ev['excess_explained']:.0f} % of the excess)"]
    phys = ev.get("physical") or {}
    stiff = {k: v["stiffness_nm_per_rad"] for k, v in phys.items() if isinstance(v, dict) and "stiffness_nm_per_rad" in v}
    if stiff:
        parts.append("stiffness " + ", ".join(f"{k} {v:.2g} N*m/rad" for k, v in stiff.items()))
    for key, unit, fmt in (("lag_deg_per_deg", "deg/deg", "{:+.2e}"), ("half_width_arcmin", "'", "{:.2f}"),
                           ("amplitude_arcsec", '"', "{:.0f}")):
        if phys.get(key):
            parts.append(key.split("_")[0] + " " + ", ".join(f"{k} {fmt.format(v)}{unit}" for k, v in phys[key].items()))
    if ev.get("description"):
        parts.append(ev["description"])
    if ev.get("confusable_with"):
        parts.append("one class with " + ", ".join(c["label"] for c in ev["confusable_with"]))
        parts.append("to separate them: " + ev.get("experiment", ""))
    if ev.get("consistency_note"):
        parts.append(ev["consistency_note"])
    return "; ".join(parts)


def effect_label(entry: dict) -> str:
    """A diagnosis finding's or undiagnosable entry's effect as ``EffectChoice.label`` names it, with the options
    that tell candidates apart (``thermal_drift(J1,2,3 tau 1 h)``): the label the diagnosis recorded, else (an
    effect the engine could not try, or an earlier diagnosis.json) the effect on its joints."""
    label = entry.get("label") or (entry.get("evidence") or {}).get("label")
    if label:
        return label
    joints = tuple(entry.get("joints") or ())
    return EffectChoice(entry["effect"], (("joints", joints),) if joints else ()).label


def render(console: Console, report: dict) -> None:
    """Rich tables: summary, the preparation (joint set, tracker drift), findings (which effect, how far it
    shrinks), where it lies, what cannot be told, and the unexplained structure (the same figures as the JSON's
    ``unexplained_structure``)."""
    floor = report["noise_floor_mm"]
    n = report["n"]
    ev = "test set" if report.get("evaluation") == "test" else "cross-validation (no test rows)"
    console.print(Text.assemble(("Sim-to-real gap", "bold"), clean(
        f" of {report['source']} ({n['calib']} calib, {n['test']} test, {n['check']} check rows; config "
        f"{report['config']})")))
    console.print(f"noise floor {floor_mm(floor)} mm from {report['noise_floor_source']} (specs "
                  f"{floor_mm(report['noise_floor_specs_mm'])} mm); geometric model "
                  f"{_mm(report['baseline_test_rms_mm'])} mm "
                  f"-> final {_mm(report['final_test_rms_mm'])} mm RMS on the {ev}", highlight=False)
    render_preparation(console, report.get("preparation"))     # read-back lag -> joint set; nest drift
    t = Table(title="Which effect, and how far the error shrinks (RMS, mm)")
    for col, just in (("effect", "left"), ("accepted", "left"), ("before", "right"), ("after", "right"),
                      ("after / floor", "right"), ("note", "right")):      # the effect's label names its joints
        t.add_column(col, justify=just)
    notes = []
    for f in report["findings"]:
        after = f["test_rms_after_mm"]
        style = "green" if f["accepted"] else ("dim" if f["evidence"].get("diagnosable", True) else "yellow")
        evidence = _short_evidence(f)
        if evidence:
            notes.append(f"{effect_label(f)}: {evidence}")
        t.add_row(effect_label(f), "yes" if f["accepted"] else "no",
                  _mm(f["test_rms_before_mm"]), _mm(after), f"{after / floor:.2f}" if after and floor else "-",
                  f"[{len(notes)}]" if evidence else "", style=style)
    console.print(keep_words(t, console.width))
    print_notes(console, notes)
    if report["where"]:
        w = Table(title="Where it lies (regions significantly above the noise floor)")
        for col, just in (("stage", "left"), ("region", "left"), ("RMS", "right"), ("floor", "right"),
                          ("ratio", "right"), ("n", "right")):
            w.add_column(col, justify=just)
        for r in report["where"]:
            w.add_row(r["stage"], r.get("region", r["description"]), _mm(r["rms_mm"]), _mm(r["floor_mm"]),
                      "-" if r.get("ratio") is None else f"{r['ratio']:.1f}", str(r["n"]))
        console.print(keep_words(w, console.width))
    else:
        console.print("where: no region of the geometric model's residual is significantly above the noise floor")
    for u in report.get("undiagnosable", []):
        console.print(Text.assemble(("cannot tell from these data:", "yellow"),
                                    clean(f" {effect_label(u)}: {u['reason']} (to reveal it: {u['remedy']})")))
    us = report.get("unexplained_structure", {})
    if us:
        console.print(clean(us["text"]), style="red" if report["unexplained"] else None)
    render_budget(console, report.get("budget"))
    render_gap(console, report)
    for note in report.get("notes", []):
        if not note.startswith("unexplained structure") and note != us.get("text"):
            console.print(f"note: {note}", highlight=False)


def render_gap(console: Console, report: dict) -> None:
    """The remainder's class, what the residual layer carries and the next steps, one line each."""
    rem = report.get("remainder")
    if rem:
        console.print(clean(f"remainder: {rem['kind']}: {rem['text']}"), highlight=False)
    layer = report.get("layer") or {}
    if layer.get("text"):
        console.print(clean(f"residual layer: {layer['text']}"), highlight=False)
    for s in report.get("next_steps") or []:
        num = (f"predicted shrinkage {s['predicted_shrinkage_mm']:.3f} mm (final -> {s['final_rms_after_mm']:.3f} mm)"
               if s["kind"] == "shrinks" else f"decides {s['at_stake_mm']:.3f} mm")
        console.print(clean(f"next: {s['class']}: {s['experiment']}; {num} ({s['basis']})"), highlight=False)


def render_self_check(console: Console, result: SelfCheckResult) -> None:
    from robocal.diagnose.selfcheck import LABELS, SHORT      # the self-check, not a report, needs its engine

    m = result.confusion()
    t = Table(title="Self-check: true effect (rows) vs diagnosed effect (columns, first accepted)")
    t.add_column("truth", no_wrap=True)
    for b in LABELS:
        t.add_column(SHORT[b], justify="right")
    for a in LABELS:
        if sum(m[a].values()):
            t.add_row(SHORT[a], *[(Text(str(m[a][b]), style="bold") if a == b else str(m[a][b])) if m[a][b] else "."
                                  for b in LABELS])
    console.print(keep_words(t, console.width))
    s = result.summary()
    e = s["shrinkage_error_mm"]
    console.print(
        f"single effects: {s['named_right']}/{s['single_trials']} correctly attributed (named, or in the named "
        f"confusable class; first accepted = truth {s['primary_correct']}, exact set {s['exact_set']}, joints right "
        f"{s['joints_ok']}); effect-free controls: {s['controls_clean']}/{s['controls']} with no effect accepted "
        f"({s['controls_unexplained']} flagged unexplained); two-effect combinations: {s['combo_exact']}/"
        f"{s['combo_trials']} exact, recall {_pct(s['combo_recall'])}, precision {_pct(s['combo_precision'])}; "
        f"outside the library: {s['outside_unexplained']}/{s['outside_trials']} flagged unexplained",
        highlight=False)
    for form, v in s["forms"].items():
        console.print(f"{form}: named right {v['named_right']}/{v['n']}, confound class named {v['confound']}/"
                      f"{v['n']}, lag called backlash {v['lag_as_backlash']}", highlight=False)
    console.print(f"read-back lag called backlash: {s['lag_as_backlash']} of {s['lag_trials']} campaigns with a lag",
                  highlight=False)
    console.print(f"spurious acceptances: {s['spurious_acceptances']} in {s['datasets']} datasets "
                  f"({s['spurious_per_20']:.2f} per 20; target <= 1)", highlight=False)
    if e["n"]:
        console.print(f"predicted (calibration CV) minus achieved (test) shrinkage over {e['n']} accepted true effects: "
                      f"mean {e['mean']:+.4f} mm, mean |error| {e['mean_abs']:.4f} mm, max |error| {e['max_abs']:.4f} mm "
                      f"(mean achieved shrinkage {e['mean_achieved']:.4f} mm)", highlight=False)
    console.print(f"{len(result.trials)} simulated campaigns in {s['seconds']:.0f} s "
                  f"({s['seconds_per_trial']:.2f} s per diagnosis)", highlight=False)


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"
