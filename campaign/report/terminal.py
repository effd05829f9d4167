"""Terminal rendering of plans and reports with rich (nothing here computes a figure)."""
from __future__ import annotations

import math

from rich.console import Console
from rich.table import Table

from robocal.effects.model import EffectChoice

from campaign.calibrate.calibration_report import STAGES, CalibrationReport
from campaign.calibrate.report_sections import LayerSummary
from campaign.calibrate.summary import taken_of_tried
from campaign.correct.verify_report import VerifyReport
from campaign.io.terminal_text import keep_words
from campaign.plan.points import Plan

from .budget_text import render_budget
from .glossary import UNCORRECTED_VS_NOMINAL
from campaign.io.quantities import condition_meaning, condition_scale, floor_mm


def _mm(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def render_stages(console: Console, report: CalibrationReport) -> None:
    """Seed 000 Table 3 rows on the held-out test set, with the noise floor ("none" without test rows)."""
    floor = report.noise_floor_mm
    if not report.n.test:
        console.print("Position error on the held-out test set: none (no test rows)", style="yellow")
    else:
        t = Table(title=f"Position error on the test set (n = {report.n.test}), mm")
        for col in ("stage", "max", "mean", "RMS", "RMS / floor"):
            t.add_column(col, justify="left" if col == "stage" else "right")
        for stage in STAGES:
            if stage.name not in report.stages:
                continue
            s = report.stages[stage.name].test
            ratio = "-" if s.rms_mm is None or not floor else f"{s.rms_mm / floor:.2f}"
            t.add_row(stage.label, _mm(s.max_mm), _mm(s.mean_mm), _mm(s.rms_mm), ratio)
        console.print(keep_words(t, console.width))
    layer = None if report.final is None else report.final.layer
    if layer:
        console.print(layer_line(layer), markup=False)
    if report.budget is not None:
        render_budget(console, report.budget.to_dict())
    render_choices(console, report)
    cv = report.residual_cv
    if cv and report.residual_choice is None:
        verdict = ("it predicts structure" if cv.gain > 0.02 else
                   "no structured residual above the noise: the layer mostly interpolates noise")
        console.print(f"residual layer ({report.method.residual}): {cv.folds}-fold CV on the calibration "
                      f"points, RMS {cv.rms_without_mm:.4f} -> {cv.rms_with_mm:.4f} mm "
                      f"({100 * cv.gain:+.0f} %): {verdict}")
    render_preparation(console, report.preparation)
    console.print(f"noise floor {floor_mm(floor)} mm (from {report.noise_floor_source}; specs "
                  f"{floor_mm(report.noise_floor_specs_mm)} mm)   {_sigma0(report)}   rejected points "
                  f"{report.n.rejected}")
    console.print(f"condition number {report.condition_number:.0f} ({condition_scale(report.condition_number)}: good "
                  f"<= 100, fair <= 10000) {condition_meaning(sum(p.identified for p in report.parameters), False)}",
                  markup=False)
    render_identity(console, report)


def layer_line(lay: LayerSummary) -> str:
    """The fitted residual layer's calibration RMS next to its CV-predicted held-out RMS, labelled."""
    gp = ""
    if lay.approximation is not None:
        how = ("exact GP" if lay.approximation == "exact" else lay.approximation if lay.n_inducing is None
               else f"inducing-point GP, {lay.n_inducing} inputs")
        if lay.joint_curve_rms_arcsec:
            how += " (" + ", ".join(f"{j} {v:.0f}\"" for j, v in lay.joint_curve_rms_arcsec.items()) + " RMS)"
        if lay.trend_rms_mm is not None:
            geo = ("" if lay.geometry_shift_rms_mm is None
                   else f" with a geometry change of {_mm(lay.geometry_shift_rms_mm)} mm RMS, together "
                        f"{_mm(lay.trend_and_shift_rms_mm)} mm RMS")
            how = f"quadratic trend {_mm(lay.trend_rms_mm)} mm RMS{geo}, then {how}"
        gp = f" ({how} on {lay.n_train} points, noise {_mm(lay.noise_mm)} mm, floor {floor_mm(lay.noise_floor_mm)} mm)"
    return (f"residual layer {lay.kind}{gp}: calibration RMS {_mm(lay.calib_rms_mm)} mm is a fit to its own "
            f"points, not an accuracy; CV-predicted held-out RMS {_mm(lay.cv_predicted_rms_mm)} mm "
            f"({lay.folds}-fold), test set {_mm(lay.test_rms_mm)} mm")


def render_identity(console: Console, report: CalibrationReport) -> None:
    """One line naming the hardware the data was measured with (when the report carries it)."""
    ident = dict(report.identification)
    r, t = ident.get("robot_identity"), ident.get("tracker_identity")
    if r and t:
        console.print(f"measured with {r.get('vendor')} {r.get('model')} ({r.get('controller_type')}, serial "
                      f"{r.get('serial')}, {r.get('software_version')}) and {t.get('vendor')} {t.get('model')} "
                      f"(serial {t.get('serial')}, firmware {t.get('firmware')})", markup=False)
    for reason in (ident.get("identity_check") or {}).get("overridden", []):
        console.print(f"identity check overridden with --force: {reason}", style="yellow", markup=False)


def render_preparation(console: Console, prep: dict | None) -> None:
    """Which joint set drove the model and why; the tracker drift the reference nests showed."""
    if not prep:
        return
    j, d = prep["joints"], prep["drift"]
    console.print(f"joints: {j['used']} ({j['why']})", markup=False)
    if d["nests"]:
        move = d["translation_at_end_mm"]
        console.print(f"tracker drift from {d['nests']} nests ({d['readings']} readings, max nest move "
                      f"{d['max_nest_move_mm']:.3f} mm): {'compensated' if d['applied'] else 'not compensated'}, "
                      f"{d['why']}; translation at the end {sum(v * v for v in move) ** 0.5:.3f} mm"
                      + (f"; CV RMS {d['cv_rms_mm']:.4f} mm" if d.get("cv_rms_mm") is not None else ""), markup=False)
        for e in d.get("excluded", []):
            console.print(f"  nest reading {e['point_id']} set aside: {e['reason']}", markup=False)


def render_choices(console: Console, report: CalibrationReport) -> None:
    """Which effects and which residual layer the data supported (CV figures), and the excluded points."""
    effects = report.effects
    sel = None if effects is None else effects.selection
    if sel:
        tried = {}                                  # per candidate: its first trial, or the one that took it
        for t in sel["trials"]:
            key = t.get("candidate", t["effect"])
            tried.setdefault(key, t)
            if t["taken"]:
                tried[key] = t
        figs = ", ".join(f"{v['effect']} {v['cv_rms_mm']:.4f}{' (taken)' if v['taken'] else ''}"
                         for v in tried.values())
        console.print(f"physical effects ({taken_of_tried(effects.counts)}; CV RMS on the calibration points, mm; "
                      f"geometry alone {sel['geometric_cv_rms_mm']:.4f}): {figs}")
        if sel.get("path"):
            console.print(f"  two paths: {sel['path']}", markup=False)
    for fe in () if effects is None else effects.fitted:
        vals = ", ".join(f"{n} {p['value']:.3g} {p['unit']}" + (f" (stiffness {p['stiffness_Nm_per_rad']:.3g} N*m/rad)"
                                                                 if "stiffness_Nm_per_rad" in p else "")
                         for n, p in fe["params"].items())
        console.print(f"  {EffectChoice.of_dict(fe).label}: {vals}")
    for note in (effects and effects.notes) or ():
        console.print(f"  note: {note}")
    ch = report.residual_choice
    if ch and ch.candidates:
        figs = ", ".join(f"{k} {v['cv_rms_mm']:.4f}" + ("" if k == "none" else f" (t {v['t']:+.1f})")
                         for k, v in ch.candidates.items())
        weak = ch.chosen != "none" and not ch.candidates.get(ch.chosen, {}).get("significant", True)
        console.print(f"residual layer by {ch.folds}-fold CV on the calibration points (RMS mm): {figs} -> "
                      f"{ch.chosen}" + (" (kept for prediction by the one-standard-error rule; t <= 3 is no evidence "
                                        "of structure)" if weak else ""), markup=False)
    w = None if ch is None else ch.without_effects
    if w:
        verdict = ("chosen: the final model leaves the effects out" if w["chosen"]
                   else "not chosen: the final model keeps the effects")
        console.print(f"without the effects ({', '.join(w['effects'])}): geometry + {w['layer']} CV RMS "
                      f"{w['cv_rms_mm']:.4f} mm against {w['cv_rms_with_effects_mm']:.4f} mm with them and "
                      f"{w['against']} (t {w['t']:+.1f}): {verdict}", markup=False)
    for e in report.excluded_points:
        console.print(f"excluded {e.point_id}: {e.reason}")
    if report.structure_note:
        console.print(report.structure_note)
    multi = report.multi_smr
    if multi and multi.skipped is None:
        figs = ", ".join(f"{k} RMS {v.rms_mm:.4f}" for k, v in multi.test.items())
        console.print(f"{multi.n_smr}-SMR calibration (one offset per SMR), test set: {figs} mm")
        o = multi.orientation_error_arcsec
        if o:
            console.print(f"flange orientation error on the test set: mean {o.mean:.1f}, RMS {o.rms:.1f}, "
                          f"max {o.max:.1f} arcsec")
    elif multi:
        console.print(f"multi-SMR calibration skipped: {multi.skipped}")


def render_parameters(console: Console, report: CalibrationReport) -> None:
    """The identified parameters of the exported model (model.json's record) and, when the model has physical
    effects, the geometry-only fit's deltas beside them, labelled."""
    geo = {r.name: r for r in report.parameters_geometry_only or ()}
    t = Table(title=parameters_title(report))
    for col in ("parameter", "delta", "std", "unit") + (("geometry-only fit",) if geo else ()):
        t.add_column(col, justify="left" if col == "parameter" else "right")
    for row in report.parameters:
        if row.identified:
            g = geo.get(row.name)
            t.add_row(row.name, f"{row.delta:+.4f}", f"{row.std:.4f}", row.unit,
                      *((f"{g.delta:+.4f}" if g else "-",) if geo else ()))
    console.print(keep_words(t, console.width))
    if report.unidentifiable:
        notes = ", ".join(f"{u.name} ({_why_fixed(u)})" for u in report.unidentifiable)
        console.print(f"fixed at nominal, not identifiable from this pose set: {notes}")


def parameters_title(report: CalibrationReport) -> str:
    """What the parameter table holds: the exported model's record, and from which fit its std come."""
    fit = f"; std from the {report.parameters_fit} fit" if report.parameters_fit else ""
    return f"Identified parameters of the exported model (model.json; delta from nominal, base relative to the " \
           f"registered frame{fit})"


def _why_fixed(u) -> str:
    """Why a parameter stayed at nominal: the parameters it is aliased with, else the reason in words."""
    return f"aliased with {'/'.join(u.redundant_with)}" if u.redundant_with else u.reason


def _vias(plan: Plan) -> str:
    n = sum(len(p.via_deg) for p in plan.points)
    return f", {n} via poses around keep-out boxes" if n else ""


def render_stop(console: Console, report: CalibrationReport) -> None:
    """``plan.stop: auto``: the predicted held-out RMS curve of the last refit, where the run stopped and why,
    and the held-out RMS the final model reached."""
    stop = report.stop
    if not stop:
        return
    t = Table(title="Predicted held-out RMS vs calibration points (last refit), mm")
    t.add_column("calibration points", justify="right")
    t.add_column("predicted RMS", justify="right")
    for n, rms in stop.last_curve:
        t.add_row(str(n) + (" (stop)" if n == stop.n_calib_at_stop else ""), f"{rms:.4f}")
    console.print(keep_words(t, console.width))
    console.print(f"stopped after {stop.n_calib_at_stop} calibration points ({stop.reason}): predicted "
                  f"held-out RMS {stop.predicted_rms_mm:.4f} mm, measured {_mm(stop.measured_rms_mm)} mm "
                  "(final model, test set)", markup=False)


def render_forecast(console: Console, fc, blocks: tuple[int, ...] = ()) -> None:
    """``campaign plan``: the parameter uncertainty the plan's calibration points predict, the calibrated model's
    own error at the test poses from it (AP(theta) RMS) and the held-out RMS to expect with the noise floor."""
    shown = [(n, math.degrees(s) if u == "rad" else float(s), "deg" if u == "rad" else u)
             for n, u, s in zip(fc.names, fc.units, fc.std)]
    text = ", ".join(f"{n} {v:.4f} {u}" for n, v, u in sorted(shown, key=lambda t: -t[1])[:4])
    console.print(f"forecast (unit-weight error 1): {len(fc.names)} geometric parameters identifiable, largest std "
                  f"{text}; O1 {fc.O1:.3g}", markup=False)
    console.print(f"condition number {fc.condition_number:.0f} ({condition_scale(fc.condition_number)}) "
                  f"{condition_meaning(len(fc.names), True)}", markup=False)
    held = (fc.floor_mm**2 + fc.model_rms_effects_mm**2) ** 0.5
    console.print(f"predicted AP(theta) RMS at the test poses from the parameter uncertainty: {fc.model_rms_mm:.4f} mm "
                  f"(geometry), {fc.model_rms_effects_mm:.4f} mm (with the pose-dependent effects); noise floor "
                  f"{floor_mm(fc.floor_mm)} mm; expected held-out RMS {held:.4f} mm if the model is complete", markup=False)
    if blocks:
        console.print(f"plan.stop: auto: refits after {', '.join(map(str, blocks))} calibration points", markup=False)


def render_selection(console: Console, sel, n_other: int, out) -> None:
    """``campaign select``: what was kept, and the AP(theta) RMS the parameter uncertainty predicts for the subset
    and for all calibration rows (``campaign.calibrate.selection.Selection``)."""
    console.print(f"selected {sel.n_chosen} of {sel.n_calib} calibration rows ({sel.criterion}), kept the "
                  f"{n_other} other rows; wrote {out}", markup=False)
    every = "" if sel.everything is None else (f", all {sel.n_calib} rows {sel.everything.model_rms_effects_mm:.4f} "
                                               "mm")
    console.print(f"predicted AP(theta) RMS from the parameter uncertainty (geometry and pose-dependent effects, at "
                  f"the {sel.judged_at}): {sel.n_chosen} rows {sel.subset.model_rms_effects_mm:.4f} mm{every}; noise floor "
                  f"{floor_mm(sel.subset.floor_mm)} mm. What the unmodelled part adds shows only in the held-out "
                  "figures of `campaign reprocess` on the subset", markup=False)
    if sel.n_chosen < sel.effects_need:
        console.print(f"note: {sel.n_chosen} rows determine the geometry but not every pose-dependent effect "
                      f"`effects: auto` may take (that needs {sel.effects_need}): a physical effect may go undetected "
                      "and stay in the residual", markup=False)


def render_plan(console: Console, plan: Plan, duration_s: float) -> None:
    console.print(f"plan {plan.sha256[:12]}: {plan.count('calib')} calib + {plan.count('test')} test points, "
                  f"{plan.count('check')} check-pose measurements, "
                  + (f"{plan.count('nest')} nest readings, " if plan.count("nest") else "")
                  + f"{len(plan.skipped)} skipped{_vias(plan)}; "
                  f"estimated duration {duration_s / 60:.1f} min")
    if plan.skipped:
        t = Table(title="Skipped points")
        for col in ("point", "set", "x", "y", "z (mm, base)", "reason"):
            t.add_column(col)
        for s in plan.skipped:
            t.add_row(s.point_id, s.set, *(f"{v:.0f}" for v in s.p_base_mm), s.reason)
        console.print(keep_words(t, console.width))


def render_verify(console: Console, rep: VerifyReport) -> None:
    """verify.json's passes: corrected and held points, figures over all and over corrected points (mm)."""
    floor = rep.noise_floor_mm
    t = Table(title=f"Verification on {rep.n} test points, mm (noise floor from the specs {floor_mm(floor)} mm)")
    for col in ("stage", "corrected", "held", "RMS all", "RMS corr.", "max corr.", "RMS corr. / floor"):
        t.add_column(col, justify="left" if col == "stage" else "right")
    fmt = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731
    for p in rep.passes:
        c = p.corrected
        t.add_row(p.stage, str(p.n_corrected), str(p.n_held), fmt(p.all.rms_mm), fmt(c and c.rms_mm),
                  fmt(c and c.max_mm), "-" if c is None else f"{c.rms_mm / floor:.2f}")
    console.print(keep_words(t, console.width))
    console.print("corrected (corr.) = points whose correction was commanded; held = commanded at their planned "
                  "joints", markup=False)
    console.print(UNCORRECTED_VS_NOMINAL, markup=False)
    for p in rep.passes:
        for why, count in p.held.items():
            console.print(f"{p.stage}: {count} held: {why}", markup=False)
    for p in rep.passes:
        a = p.orientation_error_arcsec
        if a:
            console.print(f"{p.stage}: tool orientation error {a.rms:.1f} arcsec RMS, max {a.max:.1f} "
                          f"({a.source})", markup=False)
    render_verify_drift(console, rep)


def render_verify_drift(console: Console, rep: VerifyReport) -> None:
    """The tracker drift verify removed with the reference nests: why, and the mean translation per pass (mm)."""
    d = rep.drift
    if not d:
        return
    if "nests" not in d:
        console.print(f"tracker drift: not corrected ({d.get('why', '')})", markup=False)
        return
    state = "removed" if d.get("applied") else "not removed"
    console.print(f"tracker drift from {d['nests']} nests ({d.get('readings_run', 0)} readings in the run, "
                  f"{d.get('readings_verify', 0)} in verify): {state}, {d.get('why', '')}; every measurement in "
                  f"the {d.get('frame', 'calibration frame')}", markup=False)
    for p in rep.passes:
        if p.drift_translation_mm is not None:
            t = p.drift_translation_mm
            console.print(f"{p.stage}: drift removed {t[0]:+.3f} {t[1]:+.3f} {t[2]:+.3f} mm "
                          f"(|t| {math.hypot(*t):.3f} mm, mean over the pass)", markup=False)


def render_iso(console, report: dict) -> None:
    """An ISO 9283 report: its summary (banner, targets, AP, RP with the tracker's contribution, verdict), then per
    target kind the AP table, the RP table (l-bar, S_l, measured RP, the tracker's contribution, the robot's RP and
    its 95 % interval; mm) and AD/RD; the frame, the noise floor and the RP method last."""
    from .summary_text import iso_summary_lines

    for line, style in iso_summary_lines(report):
        console.print(line, style=style or None, highlight=False)
    for run in report["runs"]:
        t = Table(title=f"ISO 9283 ({run['targets']} targets, {run['cycles']} cycles, cube edge "
                        f"{report['cube']['edge_mm']:.0f} mm)")
        for col in ("pose", "AP (mm)", "APx (mm)", "APy (mm)", "APz (mm)"):
            t.add_column(col, justify="left" if col == "pose" else "right")
        for pc in run["poses"]:
            t.add_row(pc["pose"], f"{pc['ap_mm']:.4f}", f"{pc['apx_mm']:+.4f}", f"{pc['apy_mm']:+.4f}",
                      f"{pc['apz_mm']:+.4f}")
        console.print(keep_words(t, console.width))
        t = Table(title=f"RP ({run['targets']} targets), mm: measured, the tracker's contribution, the robot's")
        for col in ("pose", "l-bar", "S_l", "RP", "tracker", "robot", "robot, 95 %"):
            t.add_column(col, justify="left" if col == "pose" else "right")
        for pc in run["poses"]:
            t.add_row(pc["pose"], f"{pc['l_mean_mm']:.4f}", f"{pc['s_l_mm']:.4f}", f"{pc['rp_mm']:.4f}",
                      f"{pc['rp_tracker_mm']:.4f}", f"{pc['rp_robot_mm']:.4f}",
                      f"{pc['rp_robot_low_mm']:.4f} .. {pc['rp_robot_high_mm']:.4f}")
        console.print(keep_words(t, console.width))
        d = run["distance"]
        console.print(f"{run['targets']}: distance {'-'.join(d['poses'])} {d['distance_cmd_mm']:.1f} mm: "
                      f"AD {d['ad_mm']:+.4f} mm, RD ±{d['rd_mm']:.4f} mm (3 S_D)", highlight=False)
    console.print(f"frame: {report['frame']}; noise floor {floor_mm(report['noise_floor_mm'])} mm (tracker and robot "
                  f"repeatability). RP: the tracker's contribution from {report['tracker_rp_source']}; verdict on "
                  f"{report['decision_rule']}", highlight=False)
    if report["cube"]["note"]:
        console.print(f"cube: {report['cube']['note']}", highlight=False)


def _sigma0(report: CalibrationReport) -> str:
    """The unit-weight error of the fit the parameter table comes from, and the geometric estimator's beside it
    when they differ (the exported model has physical effects)."""
    if report.parameters_sigma0 is None or report.parameters_fit in (None, "geometry"):
        return f"sigma0 {report.sigma0:.2f}"
    return f"sigma0 {report.parameters_sigma0:.2f} ({report.parameters_fit} fit; geometry-only {report.sigma0:.2f})"
