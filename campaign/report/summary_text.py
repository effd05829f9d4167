"""The wording of the summary (``campaign.calibrate.summary.Summary``), one owner for the terminal and the HTML
report: each line is built from the record with two callbacks, ``num(key, kind)`` (the value at ``key`` below
``summary``, formatted for its kind: ``mm``, ``ratio``, ``count``, ``value``) and ``text(str)`` (plain text: as it
is on the terminal, escaped in HTML), so the HTML can tag every number with its ``report.json`` key."""
from __future__ import annotations

from collections.abc import Callable

from campaign.calibrate.summary import FAIL, PASS, Summary

from campaign.io.quantities import FLOOR_FMT

Num = Callable[[str, str], str]
JOINT_SETS = {"readback": "read-back", "commanded": "commanded"}


def banner(s: Summary) -> str | None:
    """The SIMULATED line when a mock device took part, else None."""
    if not s.simulated:
        return None
    who = " and ".join(s.simulated_devices)
    verb, s_ = ("were", "s") if len(s.simulated_devices) > 1 else ("was", "")
    return (f"SIMULATED: the {who} {verb} simulated (mock:// driver{s_}); these figures come from a simulated "
            "cell, not from a measurement")


def origin(s: Summary) -> str | None:
    """A line when the devices are not recorded (data from a CSV: where they came from), else None."""
    if s.simulated_devices is not None:
        return None
    where = s.provenance or "devices not recorded (data from an interchange CSV)"
    return f"{where}: whether they were simulated is not known"


def model_line(s: Summary, num: Num, text: Callable[[str], str] = str) -> str:
    """The chosen model in one line: convention, parameters, effects with values, residual, joints, drift."""
    m = s.model
    conv = text(m.convention.upper())
    if m.hayati_joints:
        conv += text(", Hayati beta on ") + text(", ").join(
            text("J") + num(f"model.hayati_joints.{i}", "count") for i in range(len(m.hayati_joints)))
    params = (num("model.n_identified", "count") + text(" kinematic parameters identified (")
              + num("model.n_fixed", "count") + text(" fixed at nominal)"))
    if m.effects:
        effects = text("effects ") + text("; ").join(
            text(f"{e.label}: ") + text(", ").join(
                text(f"{v.name} ") + num(f"model.effects.{i}.values.{j}.value", "value") + text(f" {v.unit}")
                for j, v in enumerate(e.values))
            for i, e in enumerate(m.effects))
    else:
        effects = text("no physical effect")
    parts = [conv, params, effects, text(f"residual layer {m.residual}"),
             text(f"{JOINT_SETS.get(m.joints, m.joints)} joints"), text(f"drift model {m.drift}")]
    return text("model: ") + text(" | ").join(parts)


def held_out_line(s: Summary, num: Num, text: Callable[[str], str] = str) -> str:
    """The final model on the held-out test set: mean, RMS, max and RMS as a multiple of the noise floor."""
    if s.held_out is None:
        return text("held-out test set: none (no test rows): no accuracy figure; every figure of the report is a fit "
                    "to the calibration points")
    return (text("held-out test set (final model, n = ") + num("held_out.n", "count") + text("): mean ")
            + num("held_out.mean_mm", "mm") + text(", RMS ") + num("held_out.rms_mm", "mm") + text(", max ")
            + num("held_out.max_mm", "mm") + text(" mm; RMS = ") + num("rms_over_floor", "ratio")
            + text(" x the noise floor ") + num("noise_floor_mm", "floor") + text(" mm"))


def verdict_line(s: Summary, num: Num, text: Callable[[str], str] = str) -> str:
    """PASS / FAIL against the configured acceptance bounds, or why there is no verdict."""
    v = s.verdict
    bounds = [text("RMS <= ") + num("verdict.max_rms_mm", "mm") + text(" mm")] if v.max_rms_mm is not None else []
    bounds += [text("max <= ") + num("verdict.max_mm", "mm") + text(" mm")] if v.max_mm is not None else []
    if v.result in (PASS, FAIL):
        failed = text(f" (exceeded: {', '.join(v.failed)})") if v.failed else text("")
        return (text(f"verdict: {v.result.upper()} against acceptance ") + text(", ").join(bounds)
                + text(" on the held-out test set") + failed + _below_noise(v, num, text))
    hint = text(" (set acceptance.max_rms_mm, max_mm)") if not bounds else text("")
    return text(f"verdict: none: {v.result}") + hint


def _below_noise(v, num: Num, text: Callable[[str], str]) -> str:
    """The bounds a perfect model would fail on the measured noise alone, or nothing."""
    notes = {"max_rms_mm": text("RMS bound below the noise floor ") + num("noise_floor_mm", "floor") + text(" mm"),
             "max_mm": text("max bound below ") + num("verdict.noise_max_mm", "mm")
             + text(" mm, the median largest of ") + num("held_out.n", "count") + text(" errors of noise alone")}
    if not v.below_noise:
        return text("")
    which = "this bound" if len(v.below_noise) == 1 else "these bounds"
    return (text(f"; note: a perfect model would fail {which} more often than not: ")
            + text("; ").join(notes[name] for name in v.below_noise))


def reason_lines(s: Summary, text: Callable[[str], str] = str) -> list[str]:
    """Why each part of the model was chosen, one line each."""
    return [text(f"why {k}: {why}") for k, why in s.reasons.items()]


FORMATS = {"mm": ".3f", "ratio": ".2f", "count": "d", "value": ".3g", "floor": FLOOR_FMT}
"""Each kind's format on the terminal (mm as in its tables; the floor by its one owner)."""


def lookup(doc, key: str):
    """The value at dotted ``key`` of a JSON document (list indices as numbers)."""
    for part in key.split("."):
        doc = doc[int(part)] if isinstance(doc, list) else doc[part]
    return doc


def summary_lines(s: Summary) -> list[tuple[str, str]]:
    """(text, rich style) lines of the summary for the terminal, the banner first and the verdict last."""
    doc = s.to_dict()

    def num(key: str, kind: str) -> str:
        value = lookup(doc, key)
        return "-" if value is None else format(value, FORMATS[kind])
    out = [(line, "bold red") for line in (banner(s), origin(s)) if line]
    out += [(model_line(s, num), "bold")] + [("  " + line, "") for line in reason_lines(s)]
    out.append((held_out_line(s, num), "bold"))
    style = {PASS: "bold green", FAIL: "bold red"}.get(s.verdict.result, "yellow")
    return out + [(verdict_line(s, num), style)]


def render_summary(console, s: Summary | None) -> None:
    """Print the summary lines (nothing for a report without one)."""
    for line, style in summary_lines(s) if s is not None else ():
        console.print(line, style=style, markup=False, highlight=False)
