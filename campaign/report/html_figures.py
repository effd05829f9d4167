"""Figures of the HTML report, drawn only from the documents (report.json and its per-point rows, verify.json,
diagnosis, ISO 9283).

Each function takes the report (a record, or the document dict of diagnosis and ISO 9283) and returns a
:class:`Figure` (PNG bytes + title + caption), or None when the report lacks what it needs. matplotlib with the Agg
backend; one figure at a time, closed after use.
"""
from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from campaign.calibrate.calibration_report import COMPENSATED, KINEMATIC, NOMINAL, STAGES, CalibrationReport
from campaign.calibrate.report_points import PointTable
from campaign.correct.verify_report import VerifyReport

from campaign.io.quantities import floor_mm

COLORS = {NOMINAL: "tab:red", KINEMATIC: "tab:blue", COMPENSATED: "tab:green"}     # the stages drawn
DRAWN = tuple((s.name, s.short) for s in STAGES if s.name in COLORS)
_SHORT = dict(DRAWN)
SET_STYLE = {"calib": ("o", "tab:blue", "calibration"), "test": ("^", "tab:orange", "test (held out)"),
             "check": ("s", "tab:purple", "check (repeated)"), "nest": ("*", "tab:red", "reference nest")}
DPI = 80


@dataclass(frozen=True)
class Figure:
    """One report figure: a file-safe ``name``, a title, a caption and the PNG bytes."""
    name: str
    title: str
    caption: str
    png: bytes


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _subplots(rows: int, cols: int, figsize, left=0.07, right=0.98, bottom=0.13, top=0.9, wspace=0.3, hspace=0.4):
    """Figure and axes with fixed margins (a layout engine would double the drawing time of a 1000-point run)."""
    fig, axes = _plt().subplots(rows, cols, figsize=figsize, squeeze=False)
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, wspace=wspace, hspace=hspace)
    return fig, axes


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    _plt().close(fig)
    return buf.getvalue()


def _stages(err: dict) -> tuple:
    """(key, label) of the stages to draw; the final model is drawn once when it equals the kinematic one (no
    effects, no residual layer) instead of two curves on top of each other."""
    if np.array_equal(err.get(COMPENSATED), err.get(KINEMATIC), equal_nan=True):
        return ((NOMINAL, _SHORT[NOMINAL]), (KINEMATIC, f"{_SHORT[KINEMATIC]} = {_SHORT[COMPENSATED]}"))
    return DRAWN


def _points(pts: PointTable | None):
    """(sets (N,), p_base (N, 3), q_deg (N, n), {stage: |err| (N,)}) of report.json's per-point rows."""
    if pts is None:
        return None
    err = {k: np.linalg.norm(v, axis=1) for k, v in pts.err_base_mm.items()}
    return np.array(pts.set), pts.p_base_mm, pts.q_deg, err


def _test_points(pts: PointTable | None):
    """(p_base (M, 3), q_deg (M, n), {stage: |err| (M,)}) of the test points, or None without any."""
    got = _points(pts)
    if got is None:
        return None
    sets, p, q, err = got
    test = sets == "test"
    if not test.any():
        return None
    return p[test], q[test], {k: v[test] for k, v in err.items()}


# ============================================================================ calibration run
def plan_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _points(points)
    if got is None:
        return None
    sets, p, _, _ = got
    fig, axes = _subplots(1, 2, (11, 4.6), left=0.08, bottom=0.12, top=0.92, wspace=0.25)
    axes = axes[0]
    for ax, (i, j, xl, yl) in zip(axes, ((0, 1, "x (mm)", "y (mm)"), (0, 2, "x (mm)", "z (mm)"))):
        for s, (marker, color, label) in SET_STYLE.items():
            m = sets == s
            if m.any():
                ax.plot(p[m, i], p[m, j], marker, color=color, ms=4 if s != "calib" else 3, ls="none",
                        label=f"{label} ({int(m.sum())})", alpha=0.8)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].set_title("top view")
    axes[1].set_title("side view")
    axes[1].legend(loc="best", fontsize=8)
    return Figure("plan", "The plan: measured points in the robot base frame",
                  "Measured SMR positions (base frame via the calibrated registration) by set.", _png(fig))


def histogram_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _test_points(points)
    if got is None:
        return None
    p, q, err = got
    floor = report.noise_floor_mm
    stages = _stages(err)
    fig, axes = _subplots(1, len(stages), (4 * len(stages), 3.6), left=0.06 * 3 / len(stages), bottom=0.16, top=0.9,
                          wspace=0.28)
    axes = axes[0]
    for ax, (key, label) in zip(axes, stages):
        e = err[key]
        ax.hist(e[np.isfinite(e)], bins=20, color=COLORS[key], alpha=0.8)
        ax.axvline(floor, color="k", ls="--", lw=1, label=f"noise floor {floor_mm(floor)} mm")
        ax.set_title(label)
        ax.set_xlabel("|error| on test points (mm)")
        ax.set_ylabel("points")
        ax.set_xlim(left=0)
    axes[0].legend(fontsize=8)
    return Figure("histograms", "Error histograms per stage (test set)",
                  "Each stage on its own scale; the dashed line is the noise floor.", _png(fig))


def cdf_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _test_points(points)
    if got is None:
        return None
    p, q, err = got
    fig, axes = _subplots(1, 1, (7.5, 4.2), left=0.1, bottom=0.14, top=0.96)
    ax = axes[0][0]
    for key, label in _stages(err):
        e = np.sort(err[key][np.isfinite(err[key])])
        ax.step(e, np.arange(1, len(e) + 1) / len(e), where="post", color=COLORS[key], label=label)
    ax.axvline(report.noise_floor_mm, color="k", ls="--", lw=1, label="noise floor")
    ax.set_xscale("log")
    ax.set_xlabel("|error| on test points (mm, log scale)")
    ax.set_ylabel("fraction of test points")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    return Figure("cdf", "Cumulative distribution of the error per stage (test set)",
                  "Fraction of held-out points whose error is below a value.", _png(fig))


def reach_height_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _test_points(points)
    if got is None:
        return None
    p, q, err = got
    fig, axes = _subplots(1, 2, (11, 3.8), left=0.08, bottom=0.15, top=0.95, wspace=0.22)
    axes = axes[0]
    reach = np.hypot(p[:, 0], p[:, 1])
    for ax, x, xl in zip(axes, (reach, p[:, 2]), ("reach: radius from the J1 axis (mm)", "height z (mm)")):
        for key, label in _stages(err):
            ax.plot(x, err[key], ".", ms=4, color=COLORS[key], label=label, alpha=0.8)
        ax.axhline(report.noise_floor_mm, color="k", ls="--", lw=1, label="noise floor")
        ax.set_yscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel("|error| (mm, log)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return Figure("reach_height", "Error vs. reach and height (test set)", "Log scale: all stages on one axis.",
                  _png(fig))


def joints_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _test_points(points)
    if got is None:
        return None
    p, q, err = got
    n = q.shape[1]
    cols = (n + 1) // 2
    fig, axes = _subplots(2, cols, (4 * cols, 6), left=0.07, bottom=0.09, top=0.97, wspace=0.32, hspace=0.32)
    for j, ax in enumerate(axes.ravel()):
        if j >= n:
            ax.axis("off")
            continue
        for key, label in _stages(err)[1:]:
            ax.plot(q[:, j], err[key], ".", ms=5, color=COLORS[key], label=label, alpha=0.8)
        ax.axhline(report.noise_floor_mm, color="k", ls="--", lw=1, label="noise floor")
        ax.set_ylim(bottom=0)
        ax.set_xlabel(f"J{j + 1} (deg)")
        ax.set_ylabel("|error| (mm)")
        ax.grid(alpha=0.3)
    axes.ravel()[0].legend(fontsize=7)
    return Figure("joints", "Error vs. each joint after calibration (test set)",
                  "Controller joint values; the calibrated stages only (the nominal error is in the figures above).",
                  _png(fig))


def workspace_map_figure(report: CalibrationReport, points: PointTable | None) -> Figure | None:
    got = _test_points(points)
    if got is None:
        return None
    p, q, err = got
    return Figure("workspace_map", "Workspace map of the residuals, before and after (test set)",
                  "Each held-out point at its radius and height, coloured by its error; both panels on one logarithmic "
                  "colour scale, the noise floor marked on it.", _png(workspace_map(p, err, report.noise_floor_mm)))


def workspace_map(p_base_mm: np.ndarray, err: dict, floor_mm_: float | None):
    """The before (nominal) / after (final model) map of the test points' |error| (mm) over radius and height:
    one colour norm for both panels (logarithmic, from the smallest to the largest error of either), one colour bar
    with the noise floor marked. Returns the matplotlib figure."""
    from matplotlib.colors import LogNorm

    from matplotlib.ticker import FuncFormatter

    fig, axes = _subplots(1, 2, (11.5, 4.6), left=0.07, right=0.86, bottom=0.12, top=0.92, wspace=0.22)
    axes = axes[0]
    reach = np.hypot(p_base_mm[:, 0], p_base_mm[:, 1])
    both = np.concatenate([err[NOMINAL], err[COMPENSATED]])
    both = both[np.isfinite(both) & (both > 0)]
    lo, hi = (float(both.min()), float(both.max())) if len(both) else (1e-3, 1.0)
    norm = LogNorm(vmin=lo, vmax=max(hi, lo * 1.01))
    for ax, key, title in zip(axes, (NOMINAL, COMPENSATED), ("before: nominal model", "after: calibrated model")):
        sc = ax.scatter(reach, p_base_mm[:, 2], c=err[key], s=40, cmap="viridis", norm=norm)
        ax.set_title(title)
        ax.set_xlabel("radius from the J1 axis (mm)")
        ax.set_ylabel("height z (mm)")
        ax.grid(alpha=0.3)
    floor_shown = bool(floor_mm_) and lo <= floor_mm_ <= hi
    bar = fig.colorbar(sc, cax=fig.add_axes((0.885, 0.12, 0.018, 0.8)),
                       label="|error| (mm, log scale, both panels)" + ("; dashed: noise floor" if floor_shown else ""))
    bar.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    bar.ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "25" else ""))
    bar.ax.tick_params(which="minor", labelsize=7)
    if floor_shown:
        bar.ax.axhline(floor_mm_, color="w", ls="--", lw=1.5)
    return fig


def parameters_figure(report: CalibrationReport, points: PointTable | None = None) -> Figure | None:
    rows = [r for r in report.parameters if r.identified and r.std]
    if not rows:
        return None
    z = np.array([abs(r.delta) / r.std for r in rows])
    fig, axes = _subplots(1, 1, (max(7, 0.32 * len(rows)), 3.8), left=0.09, bottom=0.24, top=0.96)
    ax = axes[0][0]
    ax.bar(range(len(rows)), z, color=["tab:blue" if v >= 3 else "tab:gray" for v in z])
    ax.axhline(3, color="k", ls="--", lw=1, label="3 sigma")
    ax.set_yscale("log")
    ax.set_xticks(range(len(rows)), [r.name for r in rows], rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("|delta| / sigma (log)")
    ax.legend(fontsize=8)
    return Figure("parameters", "Identified parameters: deviation from nominal in standard deviations",
                  "Grey: within 3 sigma of nominal.", _png(fig))


def calibration_figures(report: CalibrationReport, points: PointTable | None) -> list[Figure]:
    """The calibration section's figures from the report and its per-point rows (``PointTable.of`` its ``points``)."""
    figs = (plan_figure, histogram_figure, cdf_figure, reach_height_figure, joints_figure, workspace_map_figure,
            parameters_figure)
    return [f for f in (g(report, points) for g in figs) if f is not None]


def budget_figure(budget: dict) -> Figure:
    """The error budget of report.json as a waterfall (``budget_plot``)."""
    from .budget_plot import BUDGET_CAPTION, BUDGET_TITLE, waterfall

    return Figure("budget_waterfall", BUDGET_TITLE, BUDGET_CAPTION, _png(waterfall(_plt(), budget)))


# ============================================================================ verify
def _verify_label(name: str, passes: dict) -> str:
    """A pass's tick label: its name and, from verify.json's passes, how many points were corrected and held."""
    p = passes.get(name)
    return name if p is None else f"{name}\n{p.n_corrected} corrected, {p.n_held} held"


def verify_figure(verify: VerifyReport, index: int) -> Figure:
    """RMS per verify pass on a log scale (the corrected passes sit near the floor, the uncorrected one far
    above): all test points, and the corrected points where the pass held some; the noise floor as a line."""
    plt = _plt()
    from matplotlib.ticker import FuncFormatter

    names = list(verify.stages)
    passes = {p.stage: p for p in verify.passes}
    rms_all = [verify.stages[k].rms_mm for k in names]
    rms_corr = [passes[k].corrected.rms_mm if k in passes and passes[k].n_held and passes[k].corrected else None
                for k in names]
    fig, ax = plt.subplots(figsize=(max(7, 1.9 * len(names)), 4.4), constrained_layout=True)   # small: a layout
    x = np.arange(len(names))                                                                  # engine is cheap
    split = any(v is not None for v in rms_corr)
    w = 0.38 if split else 0.6
    bars = ax.bar(x - (w / 2 if split else 0), [np.nan if v is None else v for v in rms_all], w, color="tab:blue",
                  label="all test points")
    ax.bar_label(bars, labels=["" if v is None else f"{v:.3f}" for v in rms_all], fontsize=7)
    if split:
        corr = ax.bar(x + w / 2, [np.nan if v is None else v for v in rms_corr], w, color="tab:green",
                      label="corrected points only")
        ax.bar_label(corr, labels=["" if v is None else f"{v:.3f}" for v in rms_corr], fontsize=7)
    floor = verify.noise_floor_mm
    ax.axhline(floor, color="k", ls="--", lw=1, label=f"noise floor {floor:.3f} mm")
    ax.set_yscale("log")
    shown = [v for v in (*rms_all, *rms_corr, floor) if v]
    ax.set_ylim(min(shown) / 3, max(shown) * 2)          # every bar visibly above the axis, the floor inside
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:e}"[0] in "25" else ""))
    ax.tick_params(axis="y", which="minor", labelsize=7)
    ax.set_xticks(x, [_verify_label(k, passes) for k in names], fontsize=8)
    ax.set_ylabel("RMS on the test points (mm, log scale)")
    ax.legend(fontsize=8)
    return Figure(f"verify_{index}", "Closed-loop verification: RMS per pass",
                  "Measured on the cell; log scale, so the corrected passes are readable against the noise floor. "
                  "Corrected: points whose correction was commanded; held: commanded at their planned joints.",
                  _png(fig))


# ============================================================================ ISO 9283
def iso_figures(iso: dict) -> list[Figure]:
    plt = _plt()
    out = []
    runs = iso["runs"]
    names = [pc["pose"] for pc in runs[0]["poses"]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
    width = 0.8 / len(runs)
    split = "rp_robot_mm" in runs[0]["poses"][0]
    for k, run in enumerate(runs):
        x = np.arange(len(names)) + k * width
        axes[0].bar(x, [pc["ap_mm"] for pc in run["poses"]], width, label=run["targets"])
        axes[1].bar(x, [pc["rp_mm"] for pc in run["poses"]], width, label=f"{run['targets']}, measured")
        if split:                                   # the robot's RP (tracker removed) with its 95 % interval
            robot = np.array([[pc["rp_robot_mm"], pc["rp_robot_low_mm"], pc["rp_robot_high_mm"]]
                              for pc in run["poses"]])
            axes[1].errorbar(x, robot[:, 0], yerr=[robot[:, 0] - robot[:, 1], robot[:, 2] - robot[:, 0]], fmt="o",
                             color="k", ms=3, capsize=3, label="robot (tracker removed), 95 %" if k == 0 else None)
    if split and iso.get("repeatability_spec_mm"):
        axes[1].axhline(iso["repeatability_spec_mm"], color="r", ls="--", lw=1, label="datasheet RP")
    for ax, yl in zip(axes, ("AP (mm)", "RP (mm)")):
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2, names)
        ax.set_ylabel(yl)
        ax.legend(fontsize=8)
    axes[0].set_title("pose accuracy")
    axes[1].set_title("pose repeatability")
    caption = "Barycentre error, and RP = l̄ + 3 S_l as measured (bars)" + (
        "; points: the robot's RP with the tracker's contribution removed in quadrature and its 95 % interval, "
        "against the datasheet RP (dashed)." if split else ".")
    out.append(Figure("iso9283_ap_rp", "ISO 9283: AP and RP per pose", caption, _png(fig)))
    run = runs[-1]
    dev = run.get("deviation_um")
    if dev:
        out.append(_iso_scatter(plt, names, {k: np.asarray(v, float) for k, v in dev.items()}, run["targets"]))
    return out


def _iso_scatter(plt, names: list[str], dev_um: dict, targets: str) -> Figure:
    """Attained positions around each pose's barycentre (µm): 3-D with equal axes and one scale for all poses
    (x/y only for a report written before z was kept)."""
    three = all(d.shape[1] == 3 for d in dev_um.values())
    half = max(float(np.abs(d).max()) for d in dev_um.values()) * 1.05 or 1.0
    fig = plt.figure(figsize=(3.3 * len(names), 3.7))
    fig.subplots_adjust(left=0.01 if three else 0.05, right=0.97, bottom=0.1, top=0.93, wspace=0.3)
    for k, name in enumerate(names):
        d = dev_um[name]
        ax = fig.add_subplot(1, len(names), k + 1, **({"projection": "3d"} if three else {}))
        if three:
            ax.scatter(d[:, 0], d[:, 1], d[:, 2], s=8)
            ax.set_zlim(-half, half)
            ax.set_zlabel("dz (µm)", fontsize=8, labelpad=2)
            ax.set_box_aspect((1, 1, 1))
        else:
            ax.scatter(d[:, 0], d[:, 1], s=10)
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_title(name)
        ax.set_xlabel("dx (µm)", fontsize=8)
        ax.set_ylabel("dy (µm)", fontsize=8)
        ax.tick_params(labelsize=7)
    what = "x/y/z" if three else "x/y"
    return Figure("iso9283_scatter", f"ISO 9283: attained positions around each barycentre ({targets})",
                  f"Base-frame {what} deviations of each cycle from the pose's barycentre in µm; equal scales on "
                  "every axis and every pose.", _png(fig))
