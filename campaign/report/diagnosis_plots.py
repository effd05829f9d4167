"""PNG maps of a diagnosis (workspace, joints, time, shrinkage), drawn with matplotlib when it is installed."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from campaign.run.output_dirs import Claim

from campaign.io.quantities import floor_mm


PLOTS_MISSING = "matplotlib is not importable: no plots (it is a dependency: reinstall the package)"


# ============================================================================ plots
def write_plots(report: dict, out_dir: str | os.PathLike | Claim) -> list[Path] | str:
    """PNG maps of the residual (geometric vs final model) and, with at least one accepted effect, the shrinkage
    per accepted effect into ``out_dir`` (a checked output directory is taken, i.e. created and marked, only once
    matplotlib imports). Returns the files written, or a one-line note when matplotlib is not importable."""
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
             _plot_joints(plt, maps, report, out / "where_joints.png")]
    if accepted_effects(report):
        files.append(_plot_shrinkage(plt, report, out / "shrinkage.png"))
    if "time" in maps.get("geometric", {}):
        files.append(_plot_time(plt, maps, report, out / "where_time.png"))
    if report.get("budget"):
        files.append(_plot_budget(plt, report["budget"], out / "budget_waterfall.png"))
    return files


def _save_png(fig, path: Path) -> None:
    """The figure as a PNG file written atomically (complete or absent)."""
    import io

    from campaign.io.durable import atomic_write

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write(path, buf.getvalue())


def plot_floor(report: dict) -> tuple[float, str, float | None]:
    """(floor line, its label, the repeat scatter to show dotted or None). When the diagnosis itself notes that
    the repeat scatter overestimates the floor, the line is the specs floor and the repeat scatter is dotted."""
    floor = report["noise_floor_mm"]
    over = any("floor is overestimated" in n for n in report.get("notes", []))
    if over and report.get("noise_floor_specs_mm"):
        return (report["noise_floor_specs_mm"], f"noise floor (specs) {floor_mm(report['noise_floor_specs_mm'])} mm",
                floor)
    return floor, f"noise floor ({report['noise_floor_source']}) {floor_mm(floor)} mm", None


def _floor_lines(ax, report, vertical=False):
    floor, label, repeat = plot_floor(report)
    line = ax.axvline if vertical else ax.axhline
    line(floor, color="k", ls="--", lw=1, label=label)
    if repeat is not None:
        line(repeat, color="gray", ls=":", lw=1, label=f"repeat scatter {repeat:.3f} mm (overestimated)")


def accepted_effects(report: dict) -> list[str]:
    """The effects the diagnosis accepted (its final model is the geometric one plus these): with none, the maps
    draw "geometric = final" once instead of two curves that differ by rounding."""
    return [f["effect"] for f in report["findings"] if f["accepted"]]


GEOMETRIC_IS_FINAL = "geometric = final (no effect accepted)"


def _final_label(report: dict) -> str:
    return "final (geometric + " + ", ".join(accepted_effects(report)) + ")"


def _plot_workspace(plt, maps, report, path):
    """Residual RMS per (radius, height) cell; cells without points are hatched grey and say so. One panel,
    "geometric model = final model", when no effect was accepted."""
    stages = ("geometric", "final") if accepted_effects(report) else ("geometric",)
    fig, axes = plt.subplots(1, len(stages), figsize=(11.5 if len(stages) > 1 else 7.0, 4.8),
                             constrained_layout=True, squeeze=False)
    axes = axes[0]
    vmax = max((v for st in stages for row in maps[st]["workspace"]["rms_mm"] for v in row if v is not None),
               default=report["noise_floor_mm"])
    floor, label, _ = plot_floor(report)
    for ax, st in zip(axes, stages):
        w = maps[st]["workspace"]
        grid = np.array([[np.nan if v is None else v for v in row] for row in w["rms_mm"]]).T
        ax.set_facecolor("0.9")
        ax.fill_between([w["radius_edges_mm"][0], w["radius_edges_mm"][-1]], w["z_edges_mm"][0], w["z_edges_mm"][-1],
                        hatch="//", facecolor="0.9", edgecolor="0.7", lw=0, zorder=0)
        im = ax.pcolormesh(w["radius_edges_mm"], w["z_edges_mm"], np.ma.masked_invalid(grid), vmin=0, vmax=vmax,
                           cmap="viridis", zorder=1)
        ax.set_title(("geometric model" if len(stages) > 1 else "geometric model = final model (no effect accepted)")
                     if st == "geometric" else _final_label(report) + " model", fontsize=10)
        ax.set_xlabel("radius from the J1 axis (mm)")
        ax.set_ylabel("height z (mm)")
    fig.colorbar(im, ax=axes, label="residual RMS (mm)")
    fig.suptitle(f"Residual RMS over the workspace;{' ' if len(stages) > 1 else chr(10)}{label}; hatched cells: no "
                 "points", fontsize=11)
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
    same = not accepted_effects(report)
    fig, axes = plt.subplots(2, (n + 1) // 2, figsize=(12, 6.4), constrained_layout=True, squeeze=False)
    for j, ax in enumerate(axes.ravel()):
        if j >= n:
            ax.axis("off")
            continue
        _plot_line(ax, maps["geometric"]["joints"][j], GEOMETRIC_IS_FINAL if same else "geometric", "o-")
        if not same:
            _plot_line(ax, maps["final"]["joints"][j], _final_label(report), "s-")
        _floor_lines(ax, report)
        ax.set_xlabel(maps["geometric"]["joints"][j]["label"])
        ax.set_ylabel("RMS (mm)")
        ax.set_ylim(bottom=0)
    axes.ravel()[0].legend(fontsize=8)
    gaps = any(v is None for m in maps["geometric"]["joints"] for v in m["rms_mm"])
    fig.suptitle("Residual RMS over each joint's range" + (f", {GEOMETRIC_IS_FINAL}" if same else "")
                 + ("; gaps: bins without points" if gaps else ""))
    _save_png(fig, path)
    plt.close(fig)
    return path


def _plot_time(plt, maps, report, path):
    same = not accepted_effects(report)
    fig, ax = plt.subplots(figsize=(7.5, 4), constrained_layout=True)
    _plot_line(ax, maps["geometric"]["time"], GEOMETRIC_IS_FINAL if same else "geometric", "o-")
    if "time" in maps["final"] and not same:
        _plot_line(ax, maps["final"]["time"], _final_label(report), "s-")
    _floor_lines(ax, report)
    ax.set_xlabel("t (min)")
    ax.set_ylabel("RMS (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    gaps = any(v is None for v in maps["geometric"]["time"]["rms_mm"])
    ax.set_title("Residual RMS over time" + (f", {GEOMETRIC_IS_FINAL}" if same else "")
                 + ("; gaps: intervals without points" if gaps else ""), fontsize=10)
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


def _plot_budget(plt, budget, path):
    from .budget_plot import waterfall

    fig = waterfall(plt, budget)
    _save_png(fig, path)
    plt.close(fig)
    return path
