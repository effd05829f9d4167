"""Words of the diagnosis: remedies, separating experiments, gate reasons and the evidence dict of a finding."""
from __future__ import annotations

import math

import numpy as np

from .candidates import ELASTIC_CLASS
from .engine import _overlap
from .records import DiagnosisOptions
from .scoring import _Score


REMEDY = {
    "joint_compliance": "measure with two payloads and wide J2/J3 coverage including upright poses",
    "payload_deflection": "measure with a second payload (e.g. none and the rated load), alternating in blocks",
    "gear_cyclic": "cover the joint's whole range; dense single-joint sweeps (0.05-0.2 deg) for motor-rate terms",
    "backlash": "approach the poses from random, recorded directions (or paired +/- approaches)",
    "readback_lag": "log the commanded joints next to the read-back ones (qc1..qcn) and vary the size of the moves",
    "thermal_drift": "log timestamps (and temperatures) from a cold start, poses in random order over >= 2 h",
    "axis_coupling": "mount the SMR >= 50 mm off the J6 axis and cover J4/J5 widely",
    "registration_drift": "log timestamps and re-measure 3-4 floor nests every 10-15 min",
}


SEPARATING_EXPERIMENT = {
    frozenset({"joint_compliance", "gear_cyclic"}): "compare poses with equal q2 and different q3 (a J2 harmonic "
    "cannot depend on q3, gravity compliance does), or measure with a second payload",
    frozenset({"payload_deflection", "gear_cyclic"}): "measure the same poses with and without the payload",
    frozenset({"backlash", "readback_lag"}): "log the commanded joints (qc1..qcn), or approach the same poses with "
    "short and long moves from both sides",
    frozenset({"thermal_drift", "registration_drift"}): "re-measure floor reference nests during the run (tracker "
    "drift moves the nests, thermal growth does not)",
    frozenset({"joint_compliance", "payload_deflection"}): "measure with two payloads in alternating blocks",
    frozenset({"joint_compliance", "thermal_drift"}): "measure the poses in random order over the whole run",
}


def separating_experiment(a: str, b: str) -> str:
    return SEPARATING_EXPERIMENT.get(frozenset({a, b}),
                                     "widen the range of the inputs where they differ (joints, time, payload) "
                                     "or add a second SMR for orientation")


def _cv_reason(cv: dict, opt: DiagnosisOptions) -> str:
    if cv["cv_gain_t"] < opt.cv_min_t:
        return f"cross-validated error does not fall significantly (t = {cv['cv_gain_t']:.1f})"
    return (f"removes only {100 * cv['excess_explained']:.1f} % of the cross-validated excess over the noise floor "
            f"(< {100 * opt.min_excess_fraction:.0f} %)")


def _confusion_entry(best: _Score, other: _Score) -> dict:
    return {"effect": other.cand.name, "joints": list(other.joints), "delta_bic": other.delta_bic,
            "log10_bayes_factor": (other.delta_bic - best.delta_bic) / (2.0 * math.log(10.0)),
            "overlap": _overlap(best.U, other.U),
            "experiment": separating_experiment(best.cand.name, other.cand.name)}


def _params(sc: _Score, theta: np.ndarray | None = None) -> dict:
    vals = sc.gamma if theta is None else theta
    names = [f"{g.label}:{nm}" if g.label not in nm else nm for g in sc.groups for nm in g.names]
    return dict(zip(names, (float(v) for v in vals)))


def _evidence(sc: _Score, floor: float, after: float) -> dict:
    ev = {"diagnosable": True, "delta_bic": sc.delta_bic, "f_statistic": sc.f_stat, "p_value": sc.p_value,
          "dof": sc.rank, "absorbed_fraction": sc.absorbed,
          "profile": sc.profile.label if sc.profile else None, "groups": [g.label for g in sc.groups],
          "remaining_vs_floor": after / floor if floor > 0 else None}
    if sc.cv:
        ev.update({k: v for k, v in sc.cv.items() if k != "ok"})
    if sc.plausible:
        ev["plausible"], ev["plausibility"] = sc.plausible
    if sc.gamma is not None and "parameters" not in ev:
        ev["parameters"] = _params(sc)
    conf = sc.confusable
    if conf:
        ev["confusable_with"] = conf
        ev["class"] = " / ".join([sc.cand.name] + [c["effect"] for c in conf])
        ev["experiment"] = "; ".join(dict.fromkeys(c["experiment"] for c in conf))
    if sc.cand.name == "joint_compliance":
        ev["elastic_class"] = ELASTIC_CLASS
        ev.setdefault("class", ELASTIC_CLASS)
    if sc.physical:
        ev["physical"] = sc.physical
    if sc.cand.info.get("nest_drift"):
        ev["nest_drift"] = sc.cand.info["nest_drift"]
    if "direct_comparison" in sc.cand.info:
        ev["direct_comparison"] = {f"J{j}": v for j, v in sc.cand.info["direct_comparison"].items()}
    if sc.cand.name == "readback_lag" and sc.gamma is not None:
        ev["lag_deg_per_deg"] = _lags(_params(sc))
    if np.isfinite(sc.refit_cv_t):
        ev["refit_cv_t"] = sc.refit_cv_t
    return ev


def _physical_values(name: str, params: dict) -> dict:
    """Physical reading of fitted parameters: gear amplitude per harmonic (arcsec), backlash half-width (arcmin)."""
    if name == "gear_cyclic":
        amp = {}
        for k, v in params.items():
            h = k.split(":")[-1]
            if h.startswith("sin"):
                c = params.get(k.replace("sin", "cos"), 0.0)
                amp[f"h{h[3:]}"] = math.degrees(math.hypot(v, c)) * 3600.0
        return {"amplitude_arcsec": amp}
    if name == "backlash":
        return {"half_width_arcmin": {k.split(":")[-1].replace("b", "J"): math.degrees(abs(v)) * 60.0 / 2.0
                                      for k, v in params.items()}}
    return {}


def _lags(params: dict) -> dict:
    """Read-back lag per joint (deg/deg) from the fitted parameters (-lambda)."""
    return {k.split(":")[-1].replace("lag", "J"): -v for k, v in params.items() if k.split(":")[-1].startswith("lag")}
