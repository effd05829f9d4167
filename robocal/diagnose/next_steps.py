"""What to do next, with a number from the budget: for each class the data leave undecided, the experiment
that decides it and how much of the held-out error it bears on.

* ``shrinks``: the experiment removes a budget component on these poses (excess noise of the joint readings:
  calibrate on the commanded joints; unexplained structure: the named term or more poses where it lies);
* ``decides``: the data predict equally well with either member of a class (confusable effects, an effect and a
  drift in measurement order): on these poses the error does not shrink, but the component the class carries is
  what a wrong choice costs away from them (``at_stake_mm``); an effect these data cannot reveal bears at most
  on the unexplained structure left over.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from .budget import ErrorBudget
from .jsonable import json_float
from .prose import DRIFT_EXPERIMENT

@dataclass(frozen=True)
class NextStep:
    """One undecided class: the experiment, ``kind`` ("shrinks" | "decides"), the predicted shrinkage of the
    held-out RMS (mm), the final RMS after it, what the class carries (``at_stake_mm``) and the budget components
    the number comes from (``basis``)."""
    undecided: str
    experiment: str
    kind: str
    predicted_shrinkage_mm: float
    final_rms_after_mm: float
    at_stake_mm: float
    basis: str

    def to_dict(self) -> dict:
        return {"class": self.undecided, "experiment": self.experiment, "kind": self.kind,
                "predicted_shrinkage_mm": json_float(self.predicted_shrinkage_mm),
                "final_rms_after_mm": json_float(self.final_rms_after_mm), "at_stake_mm": json_float(self.at_stake_mm),
                "basis": self.basis}

    @classmethod
    def from_dict(cls, d: Mapping) -> "NextStep":
        num = lambda k: float("nan") if d.get(k) is None else float(d[k])  # noqa: E731
        return cls(str(d["class"]), str(d["experiment"]), str(d["kind"]), num("predicted_shrinkage_mm"),
                   num("final_rms_after_mm"), num("at_stake_mm"), str(d.get("basis", "")))


COMMANDED = "log the commanded joints (qc1..qcn) next to the read-back ones and calibrate on the commanded ones"
REPEATS = "measure 10 poses x 5 repeats in random order during the run (the floor from repeats)"


def _after(R: float, shrink: float) -> float:
    return math.sqrt(max(R**2 - shrink**2, 0.0))


def next_steps(budget: ErrorBudget, remainder, findings, unexplained: dict, layer: dict, cannot=()
               ) -> list[NextStep]:
    """The next steps, largest number (predicted shrinkage or what is at stake) first."""
    R = math.sqrt(sum(c.rms_mm**2 for c in budget.components if c.kind in ("layer", "floor", "structure", "noise")))
    comp = {c.name: c.rms_mm for c in budget.components}
    noise, structure = comp.get("excess noise", 0.0), comp.get("unexplained structure", 0.0)
    lay = sum(c.rms_mm**2 for c in budget.of_kind("layer"))
    out = []
    if remainder is not None and remainder.kind == "noise" and noise > 0:
        joints = (remainder.source or "").startswith("noisy joint")
        out.append({"class": "excess noise: " + (remainder.source or "").split(" (")[0],
                    "experiment": COMMANDED if joints else REPEATS, "kind": "shrinks" if joints else "decides",
                    "predicted_shrinkage_mm": noise if joints else 0.0,
                    "final_rms_after_mm": _after(R, noise) if joints else R, "at_stake_mm": noise,
                    "basis": "budget component 'excess noise'"})
    if unexplained.get("unexplained"):
        best = (layer.get("terms") or [None])[0]
        gain = max(math.sqrt(lay + structure**2), best["gain_mm"] if best else 0.0)
        ranked = unexplained.get("where_remainder") or layer.get("regions") or []
        where = ranked[0]["region"] if ranked else None
        exp = (f"add the term {best['term']} to the model" if best and best.get("t", 0) > 2 else
               "model the structure (a term the library lacks)")
        exp += f" and measure more poses in {where}" if where else ""
        out.append({"class": "unexplained structure" + (f" ({unexplained['best_description']}, not physical)"
                                                         if unexplained.get("best_description") else ""),
                    "experiment": exp, "kind": "shrinks", "predicted_shrinkage_mm": gain,
                    "final_rms_after_mm": _after(R, gain), "at_stake_mm": gain,
                    "basis": "budget components 'residual layer' + 'unexplained structure'"})
    for f in findings:
        ev = f.evidence
        stake = comp.get(ev["label"], 0.0)
        if ev.get("confusable_with"):
            out.append({"class": ev.get("class", ev["label"]), "experiment": ev.get("experiment", ""),
                        "kind": "decides", "predicted_shrinkage_mm": 0.0, "final_rms_after_mm": R,
                        "at_stake_mm": stake, "basis": f"budget component '{ev['label']}'"})
        elif "order_confound" in ev:
            out.append({"class": " / ".join(ev["order_confound"]["class"]), "experiment": DRIFT_EXPERIMENT,
                        "kind": "decides", "predicted_shrinkage_mm": 0.0, "final_rms_after_mm": R,
                        "at_stake_mm": stake, "basis": f"budget component '{ev['label']}'"})
    for u in cannot if structure > 0 else ():     # what these data cannot reveal: at most the structure left
        out.append({"class": f"{u['effect']} (cannot tell: {u['reason']})", "experiment": u["remedy"],
                    "kind": "decides", "predicted_shrinkage_mm": 0.0, "final_rms_after_mm": R,
                    "at_stake_mm": structure, "basis": "budget component 'unexplained structure' (an upper bound)"})
    out.sort(key=lambda s: -max(s["predicted_shrinkage_mm"], s["at_stake_mm"]))
    return [NextStep.from_dict(s) for s in out]
