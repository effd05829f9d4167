"""Forward selection (strongest evidence first, through the named gates) and the backward pass that every
accepted effect must survive in the final model."""
from __future__ import annotations

import math

import numpy as np

from .candidates import Candidate
from .engine import _columns_of, _Engine, _orth, _overlap, _rms, _State, _whiten
from .prose import _confusion_entry, _cv_reason
from .records import DiagnosisOptions
from .scoring import _Score


def _forward(eng, sel, st, cands, stages, Qgeo, opt):
    """Forward stepwise selection; appends one stage per step. Returns (state, accepted scores, last scores)."""
    accepted: list[_Score] = []
    pool = [c for c in cands if c.profiles and not c.reason]
    last_scores: dict[str, _Score] = {}
    while pool and len(accepted) < opt.max_effects:
        Q, y, _ = sel.base(st)
        scores = sorted((sel.score(c, st, Q, y, Qgeo) for c in pool), key=lambda s: s.delta_bic)
        last_scores = {s.cand.key: s for s in scores}
        chosen = _pick(sel, st, scores, opt, pool)
        if chosen is None:
            break
        new = eng.fit(st.kin, st.groups + list(chosen.groups), np.concatenate([st.theta, chosen.gamma]))
        _record(chosen, accepted, scores, len(stages), opt)
        st = new
        stages.append(dict(_stage_summary(eng, st, accepted, opt), added=_added_label(chosen)))
        pool = [c for c in pool if c.key != chosen.cand.key]
        rest = chosen.cand.rest(chosen.profile, chosen.groups)      # its other groups may enter later
        if rest is not None:
            pool.append(rest)
        twin = ELASTIC_TWIN.get(chosen.cand.name)
        other = next((c for c in pool if c.name == twin and not c.extends), None)
        if other is not None and not chosen.cand.extends:     # one gravity-elastic effect: the other refines it
            pool = [c for c in pool if c is not other]
            pool.append(Candidate(chosen.cand.name, chosen.cand.joints, other.profiles, notes=chosen.cand.notes,
                                  extends=True, info=other.info))
    return st, accepted, last_scores


ELASTIC_TWIN = {"joint_compliance": "payload_deflection", "payload_deflection": "joint_compliance"}


SATURATION_PARTNER = {"backlash": "readback_lag", "readback_lag": "backlash", "joint_compliance": "payload_deflection"}


def _pick(sel, st, scores, opt, pool=()) -> _Score | None:
    """The strongest evidence (lowest ΔBIC) that passes every named gate: absorption, veto (direct comparison),
    blocked CV, physical plausibility, saturation test (backlash vs read-back lag). A better-scored candidate that
    a gate rejected and whose visible subspace overlaps the winner's is kept with it as one confusable class."""
    rejected = []
    Q = y = None
    for sc in scores:
        if sc.delta_bic >= -opt.bic_threshold:
            return None
        if sc.absorbed_min > opt.absorbed_limit:
            sc.rejected = f"{100 * sc.absorbed_min:.0f} % absorbed by the geometric model"
            continue
        if sc.cand.veto:
            sc.rejected = sc.cand.veto
            rejected.append(sc)
            continue
        sc.cv = sel.cross_validate(st, sc)
        sc.plausible = sel.plausibility(st, sc)
        if not sc.cv["ok"]:
            sc.rejected = _cv_reason(sc.cv, opt)
        elif not sc.plausible[0]:
            sc.rejected = f"implausible values: {sc.plausible[1]}"
        else:
            partner = SATURATION_PARTNER.get(sc.cand.name)
            other = next((c for c in pool if c.name == partner and c.profiles and not c.reason and not c.veto
                          and not c.extends), None)
            if other is not None:
                if Q is None:
                    Q, y, _ = sel.base(st)
                js = {j for g in sc.groups for j in g.joints}
                og = [g for g in other.profiles[0].groups if set(g.joints) & js]
                if og:
                    dbic = sel.given(st, sc, og, Q, y)
                    elastic = sc.cand.name == "joint_compliance"
                    key = "nested_test" if elastic else "saturation_test"
                    sc.physical[key] = {"delta_bic_given_" + partner: dbic}
                    if not elastic:
                        sc.physical[key]["half_width_arcmin_by_move"] = sel.half_widths(st, sc)
                    if dbic >= -opt.bic_threshold:
                        sc.rejected = (
                            f"nested test: the arm's own weight adds ΔBIC {dbic:+.1f} beyond the payload torque "
                            "(payload deflection of a balanced arm)" if elastic else "saturation test: " + (
                                "the approach offset grows with the size of the move (read-back lag); backlash adds "
                                if sc.cand.name == "backlash" else
                                "the approach offset does not grow with the move (it saturates: backlash); the lag "
                                "adds ") + f"ΔBIC {dbic:+.1f} once {partner} is modelled")
                        rejected.append(sc)
                        continue
            sc.shadowed = [r for r in rejected
                           if r.cand.name != sc.cand.name and _overlap(r.U, sc.U) > opt.overlap_min]
            return sc
        rejected.append(sc)
    return None


def _record(chosen: _Score, accepted: list, scores, step: int, opt) -> None:
    """Add the chosen score to the accepted list (or to its owner when it extends an accepted effect)."""
    if chosen.cand.extends:
        owner = next(s for s in accepted if s.cand.key == chosen.cand.key)
        owner.groups = tuple(owner.groups) + tuple(chosen.groups)
        owner.steps.append(step)
        owner.extensions.append({"step": step, "groups": [g.label for g in chosen.groups], "dof": chosen.rank,
                                 "delta_bic": chosen.delta_bic, **{k: v for k, v in chosen.cv.items() if k != "ok"}})
        return
    chosen.confusable = [_confusion_entry(chosen, o) for o in scores if o is not chosen
                         and o.delta_bic < -opt.bic_threshold and o.cand.name != chosen.cand.name
                         and o.delta_bic - chosen.delta_bic < opt.bic_threshold
                         and _overlap(chosen.U, o.U) > opt.overlap_min and not any(o is r for r in chosen.shadowed)]
    chosen.confusable += [dict(_confusion_entry(chosen, o), rejected_by=o.rejected) for o in chosen.shadowed]
    chosen.steps.append(step)
    accepted.append(chosen)


def _outliers(eng: _Engine, st: _State, opt: DiagnosisOptions) -> np.ndarray:
    rows = eng.fit_rows
    w = _whiten(eng.W[rows], eng.resid(st)[rows])
    d = np.sqrt(np.sum(w**2, axis=1) / 3.0)
    s = 1.4826 * np.median(np.abs(w))
    bad = rows[d > opt.outlier_sigma * max(s, 1e-12)]
    return bad if len(bad) < opt.outlier_max_fraction * len(rows) else np.array([], int)


def _added_label(sc: _Score) -> str:
    js = sorted({j for g in sc.groups for j in g.joints})
    label = sc.cand.name + (f" J{','.join(map(str, js))}" if js else "")
    return label + (" (more terms)" if sc.cand.extends else "")


def _stage_summary(eng, st, accepted, opt) -> dict:
    """Test RMS and pose-blocked CV RMS of the model with the accepted effects so far."""
    folds = eng.folds(False, None, opt.cv_folds, opt.seed)
    A = eng.design(st, eng.fit_rows)
    y = eng.wflat(eng.resid(st), eng.fit_rows)
    e = eng.cv_errors(A, y, folds)
    e_mm = eng.to_mm(e, eng.fit_rows)
    return {"added": "geometric model", "effects": [s.cand.key for s in accepted], "test_rms_mm": eng.test_rms(st),
            "cv_rms_mm": _rms(e_mm),
            "calib_rms_mm": _rms(eng.resid(st)[eng.fit_rows]), "n_params": A.shape[1], "_cv_w": e}


def _backward(eng, sel, st, accepted, stages, opt):
    """One backward pass: drop an accepted effect whose removal no longer costs ΔBIC < -threshold given the
    others (its fitted contribution, orthogonalised against everything else, is what removing it would cost)."""
    dropped = []
    if not accepted:
        return st, accepted, stages, dropped
    _, y, A = sel.base(st)
    rss = float(y @ y)
    proxies = []
    for sc in accepted:                 # effect-agnostic: one physical effect has one set of parameters
        split = sel.split_consistency(st, sc, _columns_of(eng, st, sc.groups))
        sc.physical["reach_split"] = split
        if split["p_value"] < opt.split_alpha and split["difference_ratio"] > opt.split_min_ratio:
            sc.split_rejected = (f"its parameters differ between near and far reach in the final model (Wald χ² "
                                 f"{split['chi2']:.0f}, p = {split['p_value']:.1g}; the two fits differ by "
                                 f"{100 * split['difference_ratio']:.0f} % of the effect): it stands in for "
                                 "structure along the reach")
            proxies.append(sc)
    for sc in accepted:
        if sc not in proxies and any(_overlap(p.U, sc.U) > opt.overlap_min for p in proxies):
            p = next(p for p in proxies if _overlap(p.U, sc.U) > opt.overlap_min)
            sc.split_rejected = (f"it overlaps {p.cand.name}, which stands in for structure along the reach: the "
                                 "same structure, not an effect of the library")
            proxies.append(sc)
    dropped += proxies
    for sc in accepted:
        if sc in proxies:
            continue
        cols, th = _columns_of(eng, st, sc.groups)
        mask = np.ones(A.shape[1], bool)
        mask[cols] = False
        by_time = sc.cand.time_effect and sel.inp.t_s is not None
        folds = eng.folds(by_time, sel.inp.t_s, opt.cv_folds, opt.seed)
        yr = eng.wflat(eng.resid(st), eng.fit_rows) + A[:, cols] @ th     # the data as the model without it sees them
        e0, e1 = eng.cv_errors(A[:, mask], yr, folds), eng.cv_errors(A, yr, folds)
        dd = np.sum(e0**2, axis=1) - np.sum(e1**2, axis=1)
        sc.refit_cv_t = float(np.mean(dd) / max(np.std(dd, ddof=1) / math.sqrt(len(dd)), 1e-300))
        if sc.refit_cv_t < opt.cv_min_t:
            dropped.append(sc)
    for sc in (accepted if len(accepted) >= 2 else ()):
        if sc in dropped:
            continue
        sc.backward_delta_bic = _removal_bic(sel, eng, st, A, rss, sc.groups)
        if sc.backward_delta_bic > -opt.bic_threshold:
            dropped.append(sc)
    pruned = False
    for sc in accepted:                 # groups (joints, terms) that the final model no longer needs
        if sc in dropped or len(sc.groups) < 2:
            continue
        for g in list(sc.groups):
            if _removal_bic(sel, eng, st, A, rss, [g]) > -opt.group_bic_margin and len(sc.groups) > 1:
                sc.groups = tuple(h for h in sc.groups if h is not g)
                sc.pruned.append(g.label)
                pruned = True
    if not dropped and not pruned:
        return st, accepted, stages, dropped
    keep = [s for s in accepted if s not in dropped]
    stages = stages[:1]
    kin = st.kin
    for i, s in enumerate(keep):
        st = eng.fit(kin, [g for s in keep[:i + 1] for g in s.groups])
        s.steps = [i + 1]
        stages.append(dict(_stage_summary(eng, st, keep[:i + 1], opt), added=_added_label(s)))
    if not keep:
        st = eng.fit(kin, [])
    return st, keep, stages, dropped


def _removal_bic(sel, eng, st, A, rss, groups) -> float:
    """ΔBIC of keeping ``groups`` in the final linearised model (negative: they are needed)."""
    cols, th = _columns_of(eng, st, groups)
    mask = np.ones(A.shape[1], bool)
    mask[cols] = False
    Qo = _orth(A[:, mask])
    d = A[:, cols] @ th
    d = d - Qo @ (Qo.T @ d)
    Xp = A[:, cols] - Qo @ (Qo.T @ A[:, cols])
    r_k = _orth(Xp, 1e-3).shape[1] if np.any(Xp) else 0
    return sel.n * math.log(rss / (rss + float(d @ d))) + r_k * sel.lnn
