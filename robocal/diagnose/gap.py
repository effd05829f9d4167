"""The gap as a whole: the error budget on held-out points (``budget``), one verdict for one finding (a
non-physical best description is unexplained structure, and "where" then ranks the regions by how much of the
remainder they hold) and what the residual layer carries (``layer_terms``).

Non-physical (``nonphysical``): a negative stiffness, a gear harmonic beyond any gearbox
(``DiagnosisOptions.nonphysical_gear_arcsec``), or parameters that differ between near and far reach or between
the halves of the run by more than the effect itself (``nonphysical_split`` x the effect's visible displacement,
and by more than ``nonphysical_split_z`` x what noise alone would give). Structure is unexplained too when a named
term outside the model (``layer_terms``) predicts held-out points (``term_t``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from robocal.identify.identification import register
from robocal.kinematics.models import smr_tracker
from robocal.measure.stats import SIGNIFICANT_GAIN
from .budget import BudgetTerms, ErrorBudget, SubsetErrors, error_budget, linear_design, shapley
from .layer_terms import describe_layer
from .leftover import best_layer, floor_scale, where_stages_of
from .records import Region


@dataclass(frozen=True, eq=False)
class Gap:
    budget: ErrorBudget
    nonphysical: tuple[dict, ...]
    verdict_text: str
    ranked: list[Region]
    layer: dict = field(default_factory=dict)
    remainder: object = None


def nonphysical(findings, opt) -> list[dict]:
    """[{label, why}] of the accepted findings whose best description is not physical."""
    out = []
    for k, f in enumerate(findings):
        ev, why = f.evidence, []
        for j, v in (ev.get("physical") or {}).items():
            if isinstance(v, dict) and v.get("stiffness_nm_per_rad", 1.0) < 0:
                why.append(f"{j} stiffness {v['stiffness_nm_per_rad']:.3g} N*m/rad is negative")
        for h, a in ((ev.get("physical") or {}).get("amplitude_arcsec") or {}).items():
            if a > opt.nonphysical_gear_arcsec:
                why.append(f"{h} amplitude {a:.0f}\" is beyond any gearbox (> {opt.nonphysical_gear_arcsec:g}\")")
        noise = ev.get("consistency_noise", {})
        for split, ratio in (ev.get("consistency") or {}).items():
            if ratio > opt.nonphysical_split and noise.get(split, 0.0) > opt.nonphysical_split_z:
                why.append(f"its parameters differ between {split} by {100 * ratio:.0f} % of the effect "
                           f"({noise[split]:.1f} x noise)")
        if why:
            out.append({"index": k, "label": ev["label"], "why": why})
    return out


def budget_and_verdict(inp, opt, data, models, resid, cv, eff_cols, effects, findings, held_err, rem, unexplained,
                       stages) -> Gap:
    """The budget, the layer's description, the verdict (updates ``unexplained`` and the findings' evidence; the
    remainder is structure when a named term predicts held-out points), the regions ranked by the remainder."""
    kin_geo, cols, fit, test, meta = data
    q, p = np.asarray(inp.q_rad, float), np.asarray(inp.p_mm, float)
    ev_rows = test if len(test) else fit
    if len(test):
        m_ev = {k: (None if v is None else np.asarray(v)[test]) for k, v in meta.items()}
        p0_ev, A_ev, _, _ = linear_design(kin_geo, cols, q[test], m_ev, effects)
        sub = SubsetErrors(cv, len(cols), eff_cols, np.asarray(A_ev), p[test] - p0_ev)
        first, last = (np.sum(r[test] ** 2, axis=1) for r in (resid[0], resid[-1]))
    else:
        sub = SubsetErrors(cv, len(cols), eff_cols)
        first, last = sub.squared(()), sub.squared(tuple(range(len(effects))))
    phi = shapley(sub.squared, len(effects), first, last, opt.seed)
    nominal = register(inp.nominal if inp.nominal is not None else inp.kin, q[fit], p[fit])
    e_nom = np.sum((p[ev_rows] - smr_tracker(nominal, q[ev_rows])) ** 2, axis=1)
    layer_name, lay = best_layer(held_err)
    floor2 = np.trace(inp.cov_mm2[ev_rows], axis1=1, axis2=2) * floor_scale(inp)
    F2 = inp.noise_floor_mm**2
    nug, sill = rem.evidence["nugget_mm"] ** 2, rem.evidence["sill_mm"] ** 2
    noise_share = (nug - F2) / (sill - F2) if sill > F2 else 0.0
    terms = BudgetTerms(e_nom, first, phi, tuple(fe.choice.label for fe in effects), last, np.sum(lay**2, axis=1),
                        layer_name, floor2, noise_share, q[ev_rows], "test" if len(test) else "cv")
    budget = error_budget(terms, opt.budget_boot, seed=opt.seed)
    layer = describe_layer(inp, opt, data, models[-1], effects, cv.blockings[0].fold, held_err)
    rem = _term_structure(rem, layer, unexplained, opt)
    bad = nonphysical(findings, opt)
    text, ranked = "", []
    if bad:
        for b in bad:
            findings[b["index"]].evidence["unexplained"] = True
        physical = tuple(k for k in range(len(effects)) if k not in {b["index"] for b in bad})
        ranked = _ranked(inp, opt, fit, test, kin_geo, _errors_without(sub, physical, cv, test), stages, meta)
        best = " + ".join(fe.choice.label for fe in effects)
        text = ("unexplained structure: the best description, " + best + ", is not physical ("
                + "; ".join(f"{b['label']}: {', '.join(b['why'])}" for b in bad) + "): structure outside the library"
                + (f"; it lies mostly in {ranked[0].region} ({100 * ranked[0].extra['share']:.0f} % of the "
                   f"remainder on {100 * ranked[0].extra['points']:.0f} % of the points)" if ranked else ""))
        detail = unexplained["detail"].removeprefix("unexplained structure: ")
        unexplained.update(unexplained=True, nonphysical=[{"label": b["label"], "why": b["why"]} for b in bad],
                           best_description=best, text=f"{text}; {detail}")
    elif unexplained["unexplained"]:
        ranked = _ranked(inp, opt, fit, test, kin_geo, held_err["final"], stages, meta)
    if ranked:
        unexplained["where_remainder"] = [{"region": r.region, "share": r.extra["share"], "points": r.extra["points"]}
                                          for r in ranked[:5]]
    return Gap(budget, tuple(bad), text, ranked, layer, rem)


def _term_structure(rem, layer: dict, unexplained: dict, opt):
    """The remainder is structure, and unexplained, when the best named term outside the model (``layer_terms``)
    predicts held-out points by the standard of a claim (paired t > ``opt.term_t`` and a gain > 2 %, as an
    effect the engine takes)."""
    best = (layer.get("terms") or [None])[0]
    if best is None or best["t"] <= opt.term_t or \
            best["rms_after_mm"] >= (1.0 - SIGNIFICANT_GAIN) * best["rms_before_mm"]:
        return rem
    why = (f"a term the model lacks predicts held-out points: {best['term']} ({best['rms_before_mm']:.3f} -> "
           f"{best['rms_after_mm']:.3f} mm cross-validated, t = {best['t']:.1f})")
    unexplained.update(unexplained=True, predicted_by_term=best["term"],
                       text=f"unexplained structure: {why}; " + unexplained["detail"].removeprefix(
                           "unexplained structure: "))
    if rem.kind == "structure":
        return rem
    return replace(rem, kind="structure", source=None, text=f"{rem.rms_mm:.3f} mm RMS over the floor that something "
                                                             f"predicts ({why}; {rem.text})")


def _errors_without(sub: SubsetErrors, physical, cv, test) -> np.ndarray:
    """Held-out error vectors (M, 3) mm of geometry + the physical effects only (linearised)."""
    cols = sub.cols(physical)
    if sub.A_ev is None:
        return cv.errors(cols)
    return sub.y_ev - sub.A_ev[:, :, cols] @ cv.fit(cols)


def _ranked(inp, opt, fit, test, kin_geo, err, stages, meta) -> list[Region]:
    """Regions of the held-out points (workspace bands and cells, joint ranges, time, payload) ordered by how much
    more of the remainder ``err`` (M, 3) they hold than their share of the points (``share``, ``points``)."""
    rows = test if len(test) else fit
    regions, _ = where_stages_of(inp, opt, rows, kin_geo, err, stages[-1]["n_params"], len(fit), meta, "remainder",
                                 every=True)
    keep = [replace(r, extra=dict(r.extra, points=r.n / len(rows))) for r in regions
            if r.kind not in ("all", "axis", "approach") and r.extra.get("share") is not None]
    keep.sort(key=lambda r: -(r.extra["share"] - r.extra["points"]))
    return keep[:opt.max_regions]
