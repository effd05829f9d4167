"""The wording of the summary (``campaign.calibrate.summary.Summary``), one owner for the terminal and the HTML
report: each line is built from the record with two callbacks, ``num(key, kind)`` (the value at ``key`` below
``summary``, formatted for its kind: ``mm``, ``ratio``, ``count``, ``value``) and ``text(str)`` (plain text: as it
is on the terminal, escaped in HTML), so the HTML can tag every number with its ``report.json`` key."""
from __future__ import annotations

from collections.abc import Callable

from campaign.calibrate.summary import FAIL, PASS, Summary
from campaign.correct.verify_report import POOLED, UNCORRECTED, VerifyReport

from campaign.io.quantities import FLOOR_FMT

Num = Callable[[str, str], str]
JOINT_SETS = {"readback": "read-back", "commanded": "commanded"}


def banner(s: Summary) -> str | None:
    """The SIMULATED line when a mock device took part, else None."""
    return simulated_banner(s.simulated_devices)


def simulated_banner(devices) -> str | None:
    """The SIMULATED line for the roles ("robot", "tracker") whose driver was ``mock://``; None for none."""
    if not devices:
        return None
    who = " and ".join(devices)
    verb, s_ = ("were", "s") if len(devices) > 1 else ("was", "")
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


def outliers_line(s: Summary, num: Num, text: Callable[[str], str] = str) -> str | None:
    """The held-out points with an absurd error, named, and the held-out figures without them (None: none)."""
    o = s.held_out_outliers
    if o is None:
        return None
    named = text(", ").join(text(f"{pt.point_id} ") + num(f"held_out_outliers.points.{i}.error_mm", "mm")
                            + text(" mm") for i, pt in enumerate(o.points[:5]))
    more = text(f" and {len(o.points) - 5} more") if len(o.points) > 5 else text("")
    it = "them" if len(o.points) > 1 else "it"
    return (text(f"{len(o.points)} held-out point{'s' if len(o.points) > 1 else ''} with an absurd error (a misread? "
                 f"{o.rule}): ") + named + more + text(f"; the figures above include {it}; without {it}: mean ")
            + num("held_out_outliers.without.mean_mm", "mm") + text(", RMS ")
            + num("held_out_outliers.without.rms_mm", "mm") + text(", max ")
            + num("held_out_outliers.without.max_mm", "mm") + text(" mm (n = ")
            + num("held_out_outliers.without.n", "count") + text(")"))


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


def verified_line(v: VerifyReport, num: Callable[..., str], text: Callable[[str], str] = str) -> str:
    """The closed-loop verification on the cell (``verify.json``): every corrected pass pooled (RMS, max, RMS as a
    multiple of verify's noise floor), the model-corrected pass and the uncorrected one; or why no corrected pass
    was measured. ``num(key, kind, scale=1.0)`` reads ``key`` of the verify document."""
    if POOLED not in v.stages:
        return text(f"verified on the cell: no corrected pass measured ({v.exit_status}: {v.reason})")
    pooled, i = f"stages.{POOLED}", next(k for k, p in enumerate(v.passes) if p.stage == POOLED)
    out = (text("verified on the cell (closed loop, ") + num("n", "count") + text(" test points; every corrected pass "
           "pooled, ") + num(f"{pooled}.n", "count") + text(" measurements"))
    if v.passes[i].n_held:
        out += text(", ") + num(f"passes.{i}.n_held", "count") + text(" of them held at their planned joints")
    out += (text("): RMS ") + num(f"{pooled}.rms_mm", "mm") + text(", max ") + num(f"{pooled}.max_mm", "mm")
            + text(" mm; RMS = ") + num(f"{pooled}.rms_mm", "ratio", 1.0 / v.noise_floor_mm)
            + text(" x the noise floor ") + num("noise_floor_mm", "floor") + text(" mm"))
    for stage in ("model-corrected", UNCORRECTED):
        if stage in v.stages:
            out += text(f"; {stage} RMS ") + num(f"stages.{stage}.rms_mm", "mm") + text(" mm")
    return out


def diagnosis_line(d: dict, num: Callable[..., str], label: Callable[[dict], str],
                   text: Callable[[str], str] = str) -> str:
    """The diagnosis's headline (``diagnosis.json``): geometric -> final RMS, the effects accepted (``label``
    names each) and whether structure remains unexplained above the noise floor."""
    on = "the test set" if d.get("evaluation") == "test" else "cross-validation"
    accepted = [label(f) for f in d["findings"] if f["accepted"]]
    out = (text("diagnosis: geometric model ") + num("baseline_test_rms_mm", "mm") + text(" -> final ")
           + num("final_test_rms_mm", "mm") + text(f" mm RMS on {on}; effects accepted: ")
           + text(", ".join(accepted) or "none"))
    us = d.get("unexplained_structure") or {}
    if d.get("unexplained"):
        out += text("; structure remains unexplained")
        if us.get("excess_over_floor_mm") is not None:
            out += (text(": ") + num("unexplained_structure.excess_over_floor_mm", "mm")
                    + text(" mm RMS over the noise floor"))
    else:
        out += text("; nothing unexplained above the noise floor")
    return out


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


FORMATS = {"mm": ".3f", "ratio": ".2f", "count": "d", "value": ".3g", "floor": FLOOR_FMT, "iso": ".4f"}
"""Each kind's format on the terminal (mm as in its tables, ``iso`` as in the ISO 9283 tables; the floor by its
one owner)."""


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
    out += [(line, "bold red") for line in (outliers_line(s, num),) if line]
    style = {PASS: "bold green", FAIL: "bold red"}.get(s.verdict.result, "yellow")
    return out + [(verdict_line(s, num), style)]


def render_summary(console, s: Summary | None) -> None:
    """Print the summary lines (nothing for a report without one)."""
    for line, style in summary_lines(s) if s is not None else ():
        console.print(line, style=style, markup=False, highlight=False)


# ------------------------------------------------------------------------------ the ISO 9283 report's summary
# ``num(key, kind)`` reads the ISO report (``campaign-iso9283/1``) from its root; the verdict's wording follows the
# decision rule of ``campaign.report.iso9283``.


def iso_targets_line(doc, text: Callable[[str], str] = str) -> str:
    """Which targets were measured, with which model, in which base frame."""
    m = doc.get("model")
    if m:
        return text(f"targets: nominal, then corrected with the calibrated model {m['path']} (sha256 "
                    f"{m['sha256'][:12]}); base frame: the model's registration")
    return text("targets: nominal only (no calibrated model; campaign iso9283 --model adds corrected targets); base "
                "frame fitted to the barycentres, so AP leaves out what a rigid frame absorbs")


def iso_ap_line(doc, num: Num, text: Callable[[str], str] = str) -> str:
    """The largest AP of each target kind against the noise floor."""
    parts = [text(f"{run['targets']} ") + num(f"runs.{i}.max_ap_mm", "iso") + text(" mm")
             for i, run in enumerate(doc["runs"])]
    return (text("AP max (largest of P1..P5): ") + text(", ").join(parts) + text("; noise floor ")
            + num("noise_floor_mm", "floor") + text(" mm"))


def iso_rp_line(doc, i: int, num: Num, text: Callable[[str], str] = str) -> str:
    """The pose of run ``i`` with the largest robot RP: measured RP, the tracker's contribution, the robot's RP
    and its 95 % interval."""
    run = doc["runs"][i]
    w = run["worst_pose"]
    k = f"runs.{i}.poses.{w}."
    return (text(f"RP, {run['targets']} targets, {run['poses'][w]['pose']} (largest robot RP): measured ")
            + num(k + "rp_mm", "iso") + text(" mm; tracker's contribution ") + num(k + "rp_tracker_mm", "iso")
            + text(" mm; robot, the tracker removed in quadrature, ") + num(k + "rp_robot_mm", "iso")
            + text(" mm (95 % interval ") + num(k + "rp_robot_low_mm", "iso") + text(" to ")
            + num(k + "rp_robot_high_mm", "iso") + text(" mm)"))


def iso_verdict_line(doc, num: Num, text: Callable[[str], str] = str) -> str:
    """PASS / FAIL / UNDECIDED of the robot's RP against the datasheet, or why there is no verdict."""
    v = doc["summary"]["verdict"]
    if v["spec_mm"] is None:
        return text("verdict: none: no datasheet repeatability (set robot.repeatability_mm)")
    spec = text("the datasheet RP ") + num("summary.verdict.spec_mm", "iso") + text(" mm (robot.repeatability_mm)")
    if v["result"] == PASS:
        return text("verdict: PASS: the robot's RP, 95 % interval included, is at or below ") + spec + text(
            " at every pose")
    if v["result"] == FAIL:
        return (text("verdict: FAIL: the robot's RP exceeds ") + spec + text(" beyond its 95 % interval at ")
                + text(", ".join(v["failed"])))
    return (text("verdict: UNDECIDED: the robot's RP interval straddles ") + spec + text(
        f" at {', '.join(v['undecided'])}: this test cannot tell (more cycles, or an instrument with a smaller "
        "contribution, narrow the interval)"))


def iso_summary_lines(doc) -> list[tuple[str, str]]:
    """(text, rich style) lines of an ISO report's summary for the terminal: the banner first, the verdict last."""
    def num(key: str, kind: str) -> str:
        value = lookup(doc, key)
        return "-" if value is None else format(value, FORMATS[kind])
    out = [(line, "bold red") for line in (simulated_banner(doc["summary"]["simulated_devices"]),) if line]
    out += [(iso_targets_line(doc), ""), (iso_ap_line(doc, num), "bold")]
    out += [(iso_rp_line(doc, i, num), "bold") for i in range(len(doc["runs"]))]
    style = {PASS: "bold green", FAIL: "bold red"}.get(doc["summary"]["verdict"]["result"], "yellow")
    return out + [(iso_verdict_line(doc, num), style)]
