"""Sim-to-real gap diagnosis of a dataset (run directory or interchange CSV) against a cell config.

``diagnose_source`` loads the data, prepares it, fits the geometry and runs the elastic stage exactly as
``reprocess`` does (``campaign.effects_stage``: the effect engine decides which effects the data support), takes
the noise floor from repeated check poses (``check`` rows) when there are enough, else from the tracker and robot
specifications of the config, and runs :func:`robocal.diagnose.diagnose` on the calibration and test rows with
that answer: the same effects, values and "after" figures as reprocess's elastic stage. The report is a plain
dict whose leading keys are the JSON contract of issue 7::

    {"noise_floor_mm", "noise_floor_source": "repeats" | "specs", "baseline_test_rms_mm", "final_test_rms_mm",
     "unexplained", "findings": [{"effect", "joints" (1-based), "accepted", "test_rms_before_mm",
     "test_rms_after_mm", "evidence": {...}}], "where": [{"description", "rms_mm", ...}], ...}

followed by detail keys (``format``, ``source``, ``undiagnosable``, ``structure``, ``stages``, ``maps``, ...).
``render`` prints it with rich; ``write_plots`` draws the maps when matplotlib (the ``plots`` extra) is
importable. The self-check (``robocal.selfcheck``) is rendered by ``render_self_check``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from rich.text import Text

from robocal.diagnose import Diagnosis, DiagnosisInput, DiagnosisOptions, FittedStage, diagnose
from robocal.elastic import EngineOptions, run_engine
from robocal.identify import IdentificationError
from robocal.kinematics import ParamLayout
from robocal.noise import noise_floor_mm
from robocal.repeats import noise_floor_from_repeats, repeat_dof
from robocal.selfcheck import LABELS, SHORT, SelfCheckResult

from .cell import calibration_options, measurement_covariance, nominal_kinematics, tracker_uncertainty
from .cell import weights_covariance
from .config import CampaignConfig
from .effects_stage import gravity_model, subset
from .errors import DataError
from .fsutil import write_json as _write_json
from .interchange import Dataset, read_csv
from .outputs import Claim
from .terminal import clean
from .log_dataset import dataset_from_log
from .plausibility import check_dataset
from .process import fit_stages
from .report import render_preparation

REPORT_FORMAT = "campaign-diagnosis/1"
MIN_CALIB_ROWS = 40
PLOTS_MISSING = "matplotlib is not installed: no plots (pip install 'robot-accuracy-campaign[plots]')"


@dataclass(frozen=True, eq=False)
class DiagnosisReport:
    report: dict
    diagnosis: Diagnosis


def load_dataset(source: str | os.PathLike) -> Dataset:
    """A run directory (its log.jsonl) or an interchange CSV; DataError when it is neither."""
    from .runlog import read_log

    path = Path(source)
    if not path.exists():
        raise DataError(str(path), "no such file or run directory")
    return dataset_from_log(read_log(path)) if path.is_dir() else read_csv(path)


def _check(ds: Dataset, cfg: CampaignConfig) -> None:
    n = len(cfg.robot.joints)
    if ds.n_joints != n:
        raise DataError(ds.source, f"has {ds.n_joints} joint columns but the config's robot has {n} joints")
    n_cal = int(ds.mask("calib").sum())
    if n_cal < MIN_CALIB_ROWS:
        raise DataError(ds.source, f"only {n_cal} calib rows: the diagnosis needs at least {MIN_CALIB_ROWS}")


def diagnosis_input(ds: Dataset, cfg: CampaignConfig, stage, baseline) -> tuple[DiagnosisInput, FittedStage, dict]:
    """The robocal input (calib + test rows of the prepared dataset ``ds``, in measurement order), the engine's
    answer of reprocess's elastic stage ``stage`` mapped to those rows, and a dict describing the floor and the
    metadata. ``baseline``: the geometric fit (reprocess's kinematic stage)."""
    _check(ds, cfg)
    check = ds.mask("check")
    use = np.flatnonzero(ds.mask("calib") | ds.mask("test"))
    p = ds.p_tracker_mm
    repeats = noise_floor_from_repeats(ds.q_deg[check], p[check]) if check.any() else None
    specs = noise_floor_mm(p[use], tracker_uncertainty(cfg), cfg.robot.repeatability_mm)
    floor, source = (repeats, "repeats") if repeats is not None else (specs, "specs")
    meta = subset(stage.meta, use)
    inp = DiagnosisInput(nominal_kinematics(cfg), np.radians(ds.q_deg[use]), p[use], measurement_covariance(cfg, p)[use],
                         ds.mask("calib")[use], ds.mask("test")[use], floor, source,
                         repeat_dof(ds.q_deg[check]) if repeats is not None else None,
                         t_s=meta["t_s"], temp_c=meta["temp_c"], payload_kg=meta["payload_kg"], order=meta["order"],
                         approach=meta["approach"], move_rad=meta["move"], prev_move_rad=meta["prev_move"],
                         gravity=gravity_model(cfg), baseline=baseline.kinematics,
                         baseline_identified=tuple(baseline.identified))
    position = np.full(len(ds), -1)
    position[use] = np.arange(len(use))
    engine, elastic, kept = stage.engine, stage.elastic, stage.kept_rows
    if engine is None:                  # effects configured (or none): the diagnosis still asks the engine
        engine = run_engine(baseline.kinematics, _identified(baseline), np.radians(ds.q_deg[kept]), p[kept],
                            weights_covariance(cfg, ds)[0][kept], subset(stage.meta, kept), gravity_model(cfg),
                            EngineOptions(folds=cfg.calibration.cv_folds), calibration_options(cfg))
        elastic = engine.elastic
    fitted = FittedStage(engine, elastic, position[kept], meta)
    payloads = None if ds.payload_kg is None else sorted({round(float(v), 3) for v in ds.payload_kg[use]})
    info = {"noise_floor_specs_mm": specs, "noise_floor_repeats_mm": repeats,
            "n": {"calib": int(ds.mask("calib").sum()), "test": int(ds.mask("test").sum()), "check": int(check.sum())},
            "metadata": {"timestamps": ds.t_s is not None, "temperatures": ds.temp_c is not None,
                         "payloads_kg": payloads, "measurement_order": "rows in measurement order (interchange CSV)",
                         "mass_model": inp.gravity.source},
            "baseline": "the kinematic stage of reprocess (same preparation, fault screen and estimator)",
            "engine": "the elastic stage of reprocess (calibration.effects: auto)" if stage.engine is not None
            else "the effect engine on reprocess's fitted rows (calibration.effects is not auto)"}
    return inp, fitted, info


def _identified(result) -> np.ndarray:
    layout = ParamLayout.of(result.kinematics)
    return np.array([layout.index(n) for n in result.identified], int)


def diagnose_dataset(ds: Dataset, cfg: CampaignConfig, options: DiagnosisOptions | None = None) -> DiagnosisReport:
    """Diagnose one dataset; the report dict leads with the JSON contract. ``options`` None: the defaults with the
    config's ``calibration.cv_folds`` (the engine answer itself always comes from reprocess's elastic stage)."""
    _check(ds, cfg)
    ds, plaus = check_dataset(ds, cfg)                      # issue 12: does this data belong to this robot?
    options = options or DiagnosisOptions(engine=EngineOptions(folds=cfg.calibration.cv_folds))
    try:
        fitted = fit_stages(ds, cfg, plaus)   # the same preparation, fits and effect engine as reprocess
        inp, stage, info = diagnosis_input(fitted.dataset, cfg, fitted.stage, fitted.geo.result)
        info["plausibility"] = plaus.to_dict()
        info["preparation"] = fitted.prep.report
        d = diagnose(inp, options, stage)
    except (IdentificationError, np.linalg.LinAlgError) as exc:
        raise DataError(ds.source, f"diagnosis failed: {exc}") from None
    body = d.to_dict()
    contract = {k: body.pop(k) for k in ("noise_floor_mm", "noise_floor_source", "baseline_test_rms_mm",
                                         "final_test_rms_mm", "unexplained", "findings", "where")}
    report = {**contract, "format": REPORT_FORMAT, "source": ds.source, "config": cfg.name, **info, **body}
    return DiagnosisReport(report, d)


def diagnose_source(source: str | os.PathLike, cfg: CampaignConfig,
                    options: DiagnosisOptions | None = None) -> DiagnosisReport:
    """``diagnose_dataset`` of a run directory or CSV (``options`` None: the engine's folds are the config's
    ``calibration.cv_folds``, as in reprocess)."""
    return diagnose_dataset(load_dataset(source), cfg, options)


def write_diagnosis_json(path: str | os.PathLike, data: dict) -> Path:
    """The report as JSON (atomic, no NaN); a missing directory is bad input."""
    path = Path(path)
    if path.parent and not path.parent.exists():
        raise DataError(str(path), "the directory does not exist")
    return _write_json(path, data)


# ============================================================================ terminal
def _mm(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def _short_evidence(f: dict) -> str:
    ev = f["evidence"]
    if not ev.get("diagnosable", True):
        return f"cannot tell: {ev.get('reason', '')}"
    if not f["accepted"]:
        return ev.get("reason", "")
    parts = [f"{ev['label']}", f"held-out {ev['cv_rms_before_mm']:.3f} -> {ev['cv_rms_after_mm']:.3f} mm "
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
    console.print(f"noise floor {_mm(floor)} mm from {report['noise_floor_source']} (specs "
                  f"{_mm(report['noise_floor_specs_mm'])} mm); geometric model {_mm(report['baseline_test_rms_mm'])} mm "
                  f"-> final {_mm(report['final_test_rms_mm'])} mm RMS on the {ev}", highlight=False)
    render_preparation(console, report.get("preparation"))     # read-back lag -> joint set; nest drift
    t = Table(title="Which effect, and how far the error shrinks (RMS, mm)")
    for col, just in (("effect", "left"), ("joints", "left"), ("accepted", "left"), ("before", "right"),
                      ("after", "right"), ("after / floor", "right"), ("evidence", "left")):
        t.add_column(col, justify=just, overflow="fold")
    for f in report["findings"]:
        after = f["test_rms_after_mm"]
        style = "green" if f["accepted"] else ("dim" if f["evidence"].get("diagnosable", True) else "yellow")
        t.add_row(f["effect"], ",".join(f"J{j}" for j in f["joints"]) or "-", "yes" if f["accepted"] else "no",
                  _mm(f["test_rms_before_mm"]), _mm(after), f"{after / floor:.2f}" if after and floor else "-",
                  _short_evidence(f), style=style)
    console.print(t)
    if report["where"]:
        w = Table(title="Where it lies (regions significantly above the noise floor)")
        for col, just in (("stage", "left"), ("region", "left"), ("RMS", "right"), ("floor", "right"),
                          ("ratio", "right"), ("n", "right")):
            w.add_column(col, justify=just, overflow="fold")
        for r in report["where"]:
            w.add_row(r["stage"], r.get("region", r["description"]), _mm(r["rms_mm"]), _mm(r["floor_mm"]),
                      "-" if r.get("ratio") is None else f"{r['ratio']:.1f}", str(r["n"]))
        console.print(w)
    else:
        console.print("where: no region of the geometric model's residual is significantly above the noise floor")
    for u in report.get("undiagnosable", []):
        js = " J" + ",".join(map(str, u["joints"])) if u.get("joints") else ""
        console.print(Text.assemble(("cannot tell from these data:", "yellow"),
                                    clean(f" {u['effect']}{js}: {u['reason']} (to reveal it: {u['remedy']})")))
    us = report.get("unexplained_structure", {})
    if us:
        console.print(clean(us["text"]), style="red" if report["unexplained"] else None)
    for note in report.get("notes", []):
        if not note.startswith("unexplained structure"):
            console.print(f"note: {note}", highlight=False)


def render_self_check(console: Console, result: SelfCheckResult) -> None:
    m = result.confusion()
    t = Table(title="Self-check: true effect (rows) vs diagnosed effect (first accepted)")
    t.add_column("truth \\ diagnosed", no_wrap=True)
    for b in LABELS:
        t.add_column(SHORT[b], justify="right")
    for a in LABELS:
        if sum(m[a].values()):
            t.add_row(SHORT[a], *[(Text(str(m[a][b]), style="bold") if a == b else str(m[a][b])) if m[a][b] else "."
                                  for b in LABELS])
    console.print(t)
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


# ============================================================================ plots (optional extra)
def write_plots(report: dict, out_dir: str | os.PathLike | Claim) -> list[Path] | str:
    """PNG maps of the residual (geometric vs final model) and the shrinkage per accepted effect into ``out_dir``
    (a checked output directory is taken, i.e. created and marked, only once matplotlib imports). Returns the
    files written, or a one-line note when matplotlib is not importable."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return PLOTS_MISSING
    out = out_dir.take() if isinstance(out_dir, Claim) else Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    maps = report["maps"]
    files = [_plot_workspace(plt, maps, report, out / "where_workspace.png"),
             _plot_joints(plt, maps, report, out / "where_joints.png"),
             _plot_shrinkage(plt, report, out / "shrinkage.png")]
    if "time" in maps.get("geometric", {}):
        files.append(_plot_time(plt, maps, report, out / "where_time.png"))
    return files


def _save_png(fig, path: Path) -> None:
    """The figure as a PNG file written atomically (complete or absent)."""
    import io

    from .fsutil import atomic_write

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write(path, buf.getvalue())


def plot_floor(report: dict) -> tuple[float, str, float | None]:
    """(floor line, its label, the repeat scatter to show dotted or None). When the diagnosis itself notes that
    the repeat scatter overestimates the floor, the line is the specs floor and the repeat scatter is dotted."""
    floor = report["noise_floor_mm"]
    over = any("floor is overestimated" in n for n in report.get("notes", []))
    if over and report.get("noise_floor_specs_mm"):
        return (report["noise_floor_specs_mm"], f"noise floor (specs) {report['noise_floor_specs_mm']:.3f} mm",
                floor)
    return floor, f"noise floor ({report['noise_floor_source']}) {floor:.3f} mm", None


def _floor_lines(ax, report, vertical=False):
    floor, label, repeat = plot_floor(report)
    line = ax.axvline if vertical else ax.axhline
    line(floor, color="k", ls="--", lw=1, label=label)
    if repeat is not None:
        line(repeat, color="gray", ls=":", lw=1, label=f"repeat scatter {repeat:.3f} mm (overestimated)")


def _same_curves(maps) -> bool:
    """True when the final model is the geometric one (no effect accepted): one curve, not two on top."""
    return maps.get("final") == maps.get("geometric")


def _plot_workspace(plt, maps, report, path):
    """Residual RMS per (radius, height) cell; cells without points are hatched grey and say so."""
    fig, axes = plt.subplots(1, 2, figsize=(11.5, 4.8), constrained_layout=True)
    vmax = max((v for st in ("geometric", "final") for row in maps[st]["workspace"]["rms_mm"] for v in row
                if v is not None), default=report["noise_floor_mm"])
    floor, label, _ = plot_floor(report)
    same = _same_curves(maps)
    for ax, st in zip(axes, ("geometric", "final")):
        w = maps[st]["workspace"]
        grid = np.array([[np.nan if v is None else v for v in row] for row in w["rms_mm"]]).T
        ax.set_facecolor("0.9")
        ax.fill_between([w["radius_edges_mm"][0], w["radius_edges_mm"][-1]], w["z_edges_mm"][0], w["z_edges_mm"][-1],
                        hatch="//", facecolor="0.9", edgecolor="0.7", lw=0, zorder=0)
        im = ax.pcolormesh(w["radius_edges_mm"], w["z_edges_mm"], np.ma.masked_invalid(grid), vmin=0, vmax=vmax,
                           cmap="viridis", zorder=1)
        ax.set_title("geometric model" if st == "geometric" else
                     ("final model = geometric (no effect accepted)" if same else "final model (with the effects)"),
                     fontsize=10)
        ax.set_xlabel("radius from the J1 axis (mm)")
        ax.set_ylabel("height z (mm)")
    fig.colorbar(im, ax=axes, label="residual RMS (mm)")
    fig.suptitle(f"Residual RMS over the workspace; {label}; hatched cells: no points", fontsize=11)
    _save_png(fig, path)
    plt.close(fig)
    return path


def _plot_line(ax, m, label, style):
    e = np.asarray(m["edges"])
    c = 0.5 * (e[1:] + e[:-1])
    y = np.array([np.nan if v is None else v for v in m["rms_mm"]])
    ax.plot(c, y, style, label=label)


def _plot_joints(plt, maps, report, path):
    n = len(maps["geometric"]["joints"])
    same = _same_curves(maps)
    fig, axes = plt.subplots(2, (n + 1) // 2, figsize=(12, 6.4), constrained_layout=True, squeeze=False)
    for j, ax in enumerate(axes.ravel()):
        if j >= n:
            ax.axis("off")
            continue
        _plot_line(ax, maps["geometric"]["joints"][j], "geometric = final (no effect accepted)" if same else "geometric",
                   "o-")
        if not same:
            _plot_line(ax, maps["final"]["joints"][j], "final", "s-")
        _floor_lines(ax, report)
        ax.set_xlabel(maps["geometric"]["joints"][j]["label"])
        ax.set_ylabel("RMS (mm)")
        ax.set_ylim(bottom=0)
    axes.ravel()[0].legend(fontsize=8)
    gaps = any(v is None for m in maps["geometric"]["joints"] for v in m["rms_mm"])
    fig.suptitle("Residual RMS over each joint's range" + ("; gaps: bins without points" if gaps else ""))
    _save_png(fig, path)
    plt.close(fig)
    return path


def _plot_time(plt, maps, report, path):
    same = _same_curves(maps)
    fig, ax = plt.subplots(figsize=(7.5, 4), constrained_layout=True)
    _plot_line(ax, maps["geometric"]["time"], "geometric = final (no effect accepted)" if same else "geometric", "o-")
    if "time" in maps["final"] and not same:
        _plot_line(ax, maps["final"]["time"], "final", "s-")
    _floor_lines(ax, report)
    ax.set_xlabel("t (min)")
    ax.set_ylabel("RMS (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    gaps = any(v is None for v in maps["geometric"]["time"]["rms_mm"])
    ax.set_title("Residual RMS over time" + ("; gaps: intervals without points" if gaps else ""))
    _save_png(fig, path)
    plt.close(fig)
    return path


def _plot_shrinkage(plt, report, path):
    key = "test_rms_mm" if report.get("evaluation") == "test" else "cv_rms_mm"
    stages = report["stages"]
    labels = [s["added"] if i == 0 else "+ " + s["added"] for i, s in enumerate(stages)]
    values = [s[key] for s in stages]
    fig, ax = plt.subplots(figsize=(max(5, 1.7 * len(labels)), 4), constrained_layout=True)
    ax.bar(range(len(values)), [0 if v is None else v for v in values], color="tab:blue")
    _floor_lines(ax, report)
    ax.set_xticks(range(len(values)), labels, rotation=20, ha="right")
    ax.set_ylabel(("test" if key == "test_rms_mm" else "cross-validated") + " RMS (mm)")
    ax.set_title("How far the error shrinks, step by step")
    ax.legend()
    _save_png(fig, path)
    plt.close(fig)
    return path
