"""The ``Diagnosis`` of a finished selection: findings (accepted, dropped, not accepted), undiagnosable
effects, where the residual lies and what is left unexplained."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .candidates import Candidate
from .engine import _columns_of, _Engine, _lstsq_scaled, _rms, _split_theta, _State
from .prose import REMEDY, _cv_reason, _evidence, _lags, _params, _physical_values
from .records import Diagnosis, DiagnosisInput, DiagnosisOptions, Finding
from .regions import _leftover, _where_stages
from .scoring import _Score, _Selector


@dataclass(frozen=True, eq=False)
class Outcome:
    """What the base fit and the forward/backward selection leave for the report. ``geo_state``: the geometric
    model ("before"); ``final``: geometry + accepted effects; ``stages``: one summary per accepted step (step 0 =
    geometric); ``last_scores``: the forward pass's last scores by candidate key; ``Qgeo``: orthonormal basis of
    the whitened geometric design on the fit rows; ``outliers``: row indices set aside."""
    eng: _Engine
    sel: _Selector
    cands: list[Candidate]
    geo_state: _State
    final: _State
    accepted: list[_Score]
    dropped: list[_Score]
    stages: list[dict]
    last_scores: dict[str, _Score]
    Qgeo: np.ndarray
    outliers: np.ndarray


def _assemble(inp: DiagnosisInput, opt: DiagnosisOptions, out: Outcome) -> Diagnosis:
    """The Diagnosis of a finished selection (pops the stages' private CV residuals)."""
    eng, sel, cands, geo_state, st = out.eng, out.sel, out.cands, out.geo_state, out.final
    accepted, dropped, stages, last_scores = out.accepted, out.dropped, out.stages, out.last_scores
    outliers, Qgeo = out.outliers, out.Qgeo
    evaluation = "test" if len(eng.test_rows) else "cv"
    key = "test_rms_mm" if evaluation == "test" else "cv_rms_mm"
    findings = _accepted_findings(eng, st, accepted, stages, key, inp.noise_floor_mm)
    final = stages[-1][key]
    for sc in dropped:
        ev = _evidence(sc, inp.noise_floor_mm, final)
        ev["reason"] = (sc.split_rejected if sc.split_rejected else
                        f"does not survive the refit with the other accepted effects (cross-validated t "
                        f"{sc.refit_cv_t:.1f} < {opt.cv_min_t:g})" if sc.refit_cv_t < opt.cv_min_t else
                        f"dropped in the backward step (ΔBIC of keeping it {sc.backward_delta_bic:.1f})")
        findings.append(Finding(sc.cand.name, sc.joints, False, final, final, ev))
    done = {s.cand.key for s in accepted} | {s.cand.key for s in dropped}
    others, undiagnosable = _other_findings(eng, sel, st, [c for c in cands if c.key not in done], last_scores,
                                            final, inp.noise_floor_mm, Qgeo, opt)
    where, maps = _where_stages(inp, opt, eng, geo_state, st, stages)
    structure, unexplained, notes = _leftover(inp, opt, eng, st, stages, inp.noise_floor_mm)
    drift = next((c.info["nest_drift"] for c in cands if c.name == "registration_drift" and c.info.get("nest_drift")),
                 None)
    if drift:
        notes.append(("tracker drift ruled out by the reference nests: " if drift["ruled_out"] else
                      "reference nests: tracker drift detected, " if drift["detected"] else
                      "reference nests: drift neither detected nor ruled out, ") + drift["summary"])
    final_regions = maps.pop("_final_regions")
    if unexplained:
        where += [r for r in final_regions if r.kind != "all"]
    for s in stages:
        s.pop("_cv_w", None)
    return Diagnosis(float(inp.noise_floor_mm), inp.noise_floor_source, stages[0][key], final, unexplained,
                     tuple(findings + others), tuple(where), tuple(undiagnosable), evaluation, structure, maps,
                     tuple(notes), len(eng.fit_rows), len(eng.test_rows), tuple(int(i) for i in outliers), st.kin,
                     tuple(zip(st.groups, _split_theta(st))), tuple(stages))


def _accepted_findings(eng, st, accepted, stages, key, floor) -> list[Finding]:
    """One finding per accepted effect: RMS before its first step and after its last, shrinkage predicted by
    calibration CV vs achieved on the test rows, parameters of the final nonlinear fit."""
    findings = []
    for sc in accepted:
        first, last = sc.steps[0], sc.steps[-1]
        before, after = stages[first - 1][key], stages[last][key]
        ev = _evidence(sc, floor, after)
        predicted = sc.cv["cv_rms_before_mm"] - sc.cv["cv_rms_after_mm"]
        predicted += sum(e["cv_rms_before_mm"] - e["cv_rms_after_mm"] for e in sc.extensions)
        achieved = sum(stages[s - 1][key] - stages[s][key] for s in sc.steps)
        ev.update(step=first, parameters=_params(sc, _columns_of(eng, st, sc.groups)[1]),
                  predicted_shrinkage_mm=predicted, achieved_shrinkage_mm=achieved)
        if sc.cand.name == "readback_lag":
            ev["lag_deg_per_deg"] = _lags(ev["parameters"])
        ev.update(_physical_values(sc.cand.name, ev["parameters"]))
        if sc.pruned:
            ev["pruned_groups"] = list(sc.pruned)
        if sc.extensions:
            ev["extended"] = sc.extensions
            ev["dof"] = sc.rank + sum(e["dof"] for e in sc.extensions)
        if sc.cand.notes:
            ev["notes"] = list(sc.cand.notes)
        findings.append(Finding(sc.cand.name, sc.joints, True, before, after, ev))
    return findings


def _other_findings(eng, sel, st, cands, last_scores, final, floor, Qgeo, opt):
    """The candidates not accepted: why not, and what adding them now would do (linearised, on the test rows);
    plus the list of what these data cannot reveal, with the experiment that would."""
    Q, y, _ = sel.base(st)
    rest, undiagnosable = [], []
    for c in cands:
        if c.veto and not c.profiles:
            ev = {"diagnosable": True, "reason": c.veto}
            ev.update({k: v for k, v in c.info.items() if k != "torque_nm"})
            rest.append((np.inf, Finding(c.name, c.joints, False, final, final, ev)))
            continue
        if c.reason or not c.profiles:
            undiagnosable.append({"effect": c.name, "joints": list(c.joints), "reason": c.reason,
                                  "remedy": REMEDY[c.name]})
            ev = {"diagnosable": False, "reason": c.reason, "remedy": REMEDY[c.name]}
            if c.info.get("nest_drift"):
                ev["nest_drift"] = c.info["nest_drift"]
            rest.append((np.inf, Finding(c.name, c.joints, False, final, final, ev)))
            continue
        sc = sel.score(c, st, Q, y, Qgeo)
        prev = last_scores.get(c.key)
        ev = _evidence(sc, floor, final)
        if sc.rank == 0:
            ev["reason"] = "no part of it is visible beyond the current model"
        elif sc.absorbed_min > opt.absorbed_limit:
            ev["diagnosable"] = False
            ev["reason"] = f"{100 * sc.absorbed_min:.0f} % absorbed by the geometric model"
            undiagnosable.append({"effect": c.name, "joints": list(c.joints), "reason": ev["reason"],
                                  "remedy": REMEDY[c.name]})
        elif sc.delta_bic >= -opt.bic_threshold:
            ev["reason"] = f"not supported by the data (ΔBIC {sc.delta_bic:.1f} >= -{opt.bic_threshold:g})"
        else:
            sc.cv = sel.cross_validate(st, sc)
            sc.plausible = sel.plausibility(st, sc)
            ev = _evidence(sc, floor, final)
            ev["reason"] = (c.veto if c.veto else prev.rejected if prev is not None and prev.rejected else
                            _cv_reason(sc.cv, opt) if not sc.cv["ok"] else
                            f"implausible values: {sc.plausible[1]}" if not sc.plausible[0] else
                            f"limit of {opt.max_effects} effects reached")
        if c.veto:
            ev["reason"] = c.veto
        if c.notes:
            ev["notes"] = list(c.notes)
        after = _what_if(eng, st, sc, opt) if sc.rank else final
        rest.append((sc.delta_bic, Finding(c.name, sc.joints, False, final, after, ev)))
    return [f for _, f in sorted(rest, key=lambda x: x[0])], undiagnosable


def _what_if(eng: _Engine, st: _State, sc: _Score, opt: DiagnosisOptions) -> float:
    """Test (or CV) RMS if the candidate's selected groups were added, from the linearised joint fit."""
    rows = eng.fit_rows
    A1 = eng.design(st, rows, sc.groups)
    y = eng.wflat(eng.resid(st), rows)
    beta = _lstsq_scaled(A1, y)
    if len(eng.test_rows) == 0:
        e = eng.cv_errors(A1, y, eng.folds(False, None, opt.cv_folds, opt.seed))
        return _rms(eng.to_mm(e, rows))
    T = eng.test_rows
    parts = [st.J[T][:, :, eng.cols]] + [eng.regressor(st.J, st.kin, g)[T] for g in list(st.groups) + list(sc.groups)]
    At = np.concatenate(parts, axis=2)
    r = eng.resid(st)[T] - At @ beta
    return _rms(r)
