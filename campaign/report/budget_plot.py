"""The error budget as a waterfall (matplotlib), drawn from the JSON ``budget`` of a diagnosis or report."""
from __future__ import annotations

import numpy as np

BUDGET_TITLE = "Error budget: the nominal held-out error, cause by cause"
BUDGET_CAPTION = ("Waterfall in quadrature on a log scale: from the nominal model's held-out RMS, each bar removes one "
                  "component (its RMS and interval on the label), from the held-out RMS before it to the RMS left "
                  "after it; the noise floor is drawn last, and what is left after it is what the budget does not "
                  "close.")
COLORS = {"geometry": "tab:blue", "effect": "tab:green", "layer": "tab:olive", "floor": "tab:gray",
          "structure": "tab:red", "noise": "tab:orange"}


def waterfall(plt, budget: dict):
    """A figure of the budget (dict: ``components`` [{name, kind, rms_mm, low_mm, high_mm}], ``nominal_rms_mm``)."""
    order = {"floor": 1}                       # drawn last: what no model removes
    comps = sorted(budget["components"], key=lambda c: order.get(c.get("kind"), 0))
    nominal = float(budget["nominal_rms_mm"])
    left = nominal**2
    rows = []
    for c in comps:
        v = float(c["rms_mm"] or 0.0)
        before = np.sqrt(max(left, 0.0))
        left -= v**2
        rows.append((c, before, np.sqrt(max(left, 0.0))))
    shown = [float(c["rms_mm"]) for c in comps if c["rms_mm"] and c["rms_mm"] > 1e-3 * nominal]
    lo = max(min(shown + [nominal]) / 3.0, nominal * 1e-4)
    fig, ax = plt.subplots(figsize=(9.5, 0.42 * (len(rows) + 1) + 1.2))
    fig.subplots_adjust(left=0.34, right=0.97, bottom=0.16, top=0.9)
    y = np.arange(len(rows) + 1)[::-1]
    ax.barh(y[0], nominal - lo, left=lo, color="k", alpha=0.7)
    ax.text(nominal, y[0], f" {nominal:.3f}", va="center", fontsize=8)
    for (c, before, after), yy in zip(rows, y[1:]):
        start = max(after, lo)
        ax.barh(yy, max(before - start, 0.0), left=start, color=COLORS.get(c.get("kind"), "tab:purple"))
        ax.text(max(before, lo), yy, f" {c['rms_mm']:.3f} [{c['low_mm']:.3f}-{c['high_mm']:.3f}]", va="center",
                fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(lo, nominal * 30.0)
    ax.set_yticks(y, ["nominal held-out RMS"] + [c["name"] for c in comps], fontsize=8)
    ax.set_xlabel("held-out RMS left (mm, log scale)")
    ax.set_title(f"closure error {100 * (budget.get('closure') or 0.0):.1f} % of the nominal RMS", fontsize=9)
    return fig
