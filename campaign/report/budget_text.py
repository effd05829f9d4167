"""The error budget in the terminal (``diagnose`` and ``reprocess``): a table of the components and the closure
line, from the JSON ``budget`` (nothing here computes a figure)."""
from __future__ import annotations

from rich.console import Console
from rich.table import Table

from campaign.io.terminal_text import clean, keep_words


def _mm(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def render_budget(console: Console, budget: dict | None) -> None:
    """The error budget as a table (mm RMS on the held-out points, interval) and its closure line."""
    if not budget:
        return
    where = "test points" if budget["evaluation"] == "test" else "cross-validated calibration points"
    t = Table(title=f"Error budget: what the nominal model's error is made of (RMS on {budget['n_points']} held-out "
                    f"{where}, mm)")
    for col, just in (("component", "left"), ("RMS", "right"), ("interval", "right"), ("share", "right")):
        t.add_column(col, justify=just)
    total = budget["nominal_rms_mm"] or 0.0
    for c in budget["components"]:
        share = "-" if not total or c["rms_mm"] is None else f"{100 * c['rms_mm'] ** 2 / total ** 2:.1f} %"
        t.add_row(c["name"], _mm(c["rms_mm"]), f"{_mm(c['low_mm'])}-{_mm(c['high_mm'])}", share)
    console.print(keep_words(t, console.width))
    console.print(clean(f"closure: the components add in quadrature to {_mm(budget['sum_rms_mm'])} mm against the "
                        f"nominal held-out RMS {_mm(budget['nominal_rms_mm'])} mm (closure error "
                        f"{100 * (budget['closure'] or 0.0):.1f} %); attribution: {budget['attribution']}; interval: "
                        f"{budget['interval']}"), highlight=False)
