"""Terminal text of adaptive selection: ``campaign select --adaptive``'s rounds, the learning curves (the forecast
``campaign plan`` prints, the measured one a run's report holds) and the campaign's measuring time."""
from __future__ import annotations

from rich.console import Console
from rich.table import Table

from campaign.io.terminal_text import keep_words


def _mm(v) -> str:
    return "-" if v is None else f"{v:.4f}"


def render_adaptive_selection(console: Console, sel, n_other: int, out) -> None:
    """``campaign select --adaptive``: the seed, every round (rows before it, the layer the refit chose, its CV
    held-out RMS and the RMS predicted after the batch), and what was written."""
    n = len(sel.order)
    console.print(f"selected {n} of {sel.n_calib} calibration rows ({sel.criterion}; a space-filling seed of "
                  f"{sel.n_seed}, then {len(sel.rounds)} rounds, each chosen with only the rows chosen before it), "
                  f"kept the {n_other} other rows; wrote {out}", markup=False)
    if not sel.rounds:
        return
    t = Table(title="Rounds (held-out figures predicted from the rows chosen so far)")
    for col in ("rows", "layer", "CV RMS (mm)", "predicted after (mm)", "added"):
        t.add_column(col, justify="left" if col == "layer" else "right")
    for r in sel.rounds:
        t.add_row(str(r.n_before), r.layer, _mm(r.cv_rms_mm), _mm(r.predicted_rms_mm),
                  str(len(r.added)) + (f" ({r.note})" if r.note else ""))
    console.print(keep_words(t, console.width))


def render_plan_learning(console: Console, curve, minutes: dict) -> None:
    """``campaign plan``: the forecast learning curve (calibration poses -> predicted held-out RMS, mm) and the
    measuring time (minutes: ``plan``, ``budget`` for an adaptive plan's whole pose budget, ``grid``)."""
    if curve:
        t = Table(title="Forecast learning curve (noise model + parameter priors; the unmodelled part not included)")
        t.add_column("calibration poses", justify="right")
        t.add_column("predicted held-out RMS (mm)", justify="right")
        for n, rms in curve:
            t.add_row(str(n), f"{rms:.4f}")
        console.print(keep_words(t, console.width))
    text = f"measuring time {minutes['plan']:.1f} min"
    if minutes.get("budget") is not None:
        text += f" for the seed, test set and checks, up to {minutes['budget']:.1f} min with the whole pose budget"
    if minutes.get("grid") is not None:
        text += f"; the full grid {minutes['grid']:.1f} min"
    console.print(text + " (motion at the speed caps, settling and tracker readings)", markup=False)


def render_learning(console: Console, learning) -> None:
    """A run's ``learning`` (``LearningCurve``): the forecast and the measured held-out RMS side by side, and the
    robot minutes measured against the plan's and the full grid's."""
    if learning is None:
        return
    fc, ms = dict(learning.forecast), dict(learning.measured)
    t = Table(title="Learning curve: held-out RMS (mm) after n calibration points, forecast before the run and "
                    "measured (the first n points refitted)")
    for col in ("calibration points", "forecast", "measured"):
        t.add_column(col, justify="right")
    for n in sorted(set(fc) | set(ms)):
        t.add_row(str(n), _mm(fc.get(n)), _mm(ms.get(n)))
    console.print(keep_words(t, console.width))
    text = f"measuring time {learning.minutes_measured:.1f} min for the points measured"
    if learning.minutes_planned is not None:
        text += f" (planned {learning.minutes_planned:.1f} min)"
    if learning.minutes_grid is not None:
        text += f"; the full grid {learning.minutes_grid:.1f} min"
    text += " (motion at the speed caps, settling and tracker readings)"
    if learning.minutes_logged is not None:
        text += f"; the log's clock: {learning.minutes_logged:.1f} min"
    console.print(text, markup=False)
