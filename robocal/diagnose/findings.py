"""Findings of the diagnosis from the engine's answer: one per accepted effect (how far it shrinks the error, its
physical reading, its confusable class, confounds with the order, consistency), one per candidate not taken
(why not, what it would have given), and what the data cannot tell (with the experiment that would)."""
from __future__ import annotations

import numpy as np

from robocal.effects.engine import EngineResult
from robocal.effects.physical import reading
from robocal.effects.select import alternatives
from .evidence import confound, consistency, rival_class, visible
from .prose import REMEDY, best_available, separating_experiment
from .records import DiagnosisOptions, Finding


def accepted_findings(engine: EngineResult, effects, stages, key, ctx, opt: DiagnosisOptions) -> list[Finding]:
    """One finding per accepted effect (``effects``: FittedEffect of the final model, in step order)."""
    sel = engine.selection
    floor = ctx["floor"]
    geo_excess = max(stages[0]["cv_rms_mm"] ** 2 - floor**2, 1e-12)
    out = []
    for k, (fe, step) in enumerate(zip(effects, sel.steps)):
        eff = fe.choice.build(ctx["n"])
        phys = reading(fe, ctx["kin"], ctx["q"], ctx["meta"], ctx["gravity"], opt.engine.library)
        before_cv, after_cv = stages[k]["cv_rms_mm"], stages[k + 1]["cv_rms_mm"]
        ev = {"diagnosable": True, "label": fe.choice.label, "step": k + 1,
              "cv_rms_before_mm": before_cv, "cv_rms_after_mm": after_cv,
              "cv_blocking": " and ".join(sel.blockings), "cv_gain_t": step.t, "cv_gain": step.gain,
              "selection": {"round": step.round, "cv_rms_before_mm": step.before_mm, "cv_rms_after_mm": step.after_mm,
                            "cv_rms_by_blocking_mm": step.by_blocking_mm, "t": step.t, "gain": step.gain},
              "excess_explained": (before_cv**2 - after_cv**2) / geo_excess,
              "parameters": fe.to_dict()["params"], "physical": phys["quantities"], "plausible": phys["plausible"]}
        if not phys["plausible"]:
            ev["outside_range"] = phys["outside"]
            ev["description"] = best_available(fe.choice.label, phys)
        if step.note:
            ev["chosen_among_equals"] = step.note
        if step.pruned:
            ev["pruned_parts"] = [{"part": lb, "t": t} for lb, t in step.pruned]
        conf, c = _class(fe, eff, k, step, sel, ctx, opt)
        if c is not None:
            ev["order_confound"] = c
        if conf:
            ev["confusable_with"] = conf
            ev["class"] = " / ".join([fe.choice.label] + [x["label"] for x in conf])
            ev["experiment"] = "; ".join(dict.fromkeys(x["experiment"] for x in conf))
        split, split_noise = consistency(ctx["A_w"], ctx["y_w"], ctx["cols"][k], ctx["halves"], ctx["geo_cols"])
        ev["consistency"] = split
        ev["consistency_noise"] = split_noise
        differ = [n for n, v in split.items() if v > opt.split_min_ratio]
        if differ:
            ev["consistency_note"] = (f"its parameters differ between {' and between '.join(differ)} by "
                                      f"{', '.join(f'{100 * split[n]:.0f} %' for n in differ)} of the effect: it may "
                                      "also stand for structure outside the library (evidence, not a veto)")
        if fe.choice.name in ("joint_compliance", "payload_deflection") and ctx["gravity"].source == "default":
            ev["mass_model"] = ("default link masses (no robot.mass_kg or robot.link_masses_kg in the config): the "
                                "stiffness scales with the true moving mass")
        before, after = stages[k][key], stages[k + 1][key]
        out.append(Finding(fe.choice.name, tuple(eff.joints), True, before, after, ev))
    return out


def _class(fe, eff, k, step, sel, ctx, opt) -> tuple[list[dict], dict | None]:
    """(the confusable class of an accepted effect: rivals that predicted as well, candidates it explains
    entirely, a drift in measurement order it is confounded with; the confound itself or None)."""
    conf = rival_class(step, [s for s in sel.steps if s.round > step.round])
    conf += [{"effect": lb.split("(")[0], "label": lb, "share_explained": share,
              "experiment": separating_experiment(fe.choice.name, lb.split("(")[0], f"{fe.choice.label} {lb}"),
              "why": f"{fe.choice.label} explains {100 * share:.0f} % of its signature beyond the geometry"}
             for lb, (by, share) in sel.shadowed.items() if by == fe.choice.label
             and lb.split("(")[0] != fe.choice.name and all(lb != x["label"] for x in conf)]
    basis = eff.basis(ctx["kin_geo"], ctx["q"], ctx["meta"])
    signal = (basis.dq @ fe.values)[:, list(np.array(eff.joints) - 1)] if basis.dq is not None and eff.joints \
        else visible(ctx["R"][k] @ fe.values, ctx["J_geo"])
    c = confound(fe.choice.name, fe.choice.label, signal, ctx["q"], ctx["meta"].get("order"),
                 dict(fe.choice.options).get("clock"), opt.confound_r)
    if c is not None:
        conf.append({"effect": "registration_drift" if fe.choice.name != "registration_drift" else
                     "pose effects of the joints that follow the order", "label": c["class"][-1],
                     "experiment": c["experiment"]})
    return conf, c


def other_findings(engine: EngineResult, final: float, opt: DiagnosisOptions, n: int
                   ) -> tuple[list[Finding], list[dict]]:
    """(findings of the candidates not taken, the list of what these data cannot tell)."""
    sel = engine.selection
    taken = {c.label for c in sel.taken} | set(sel.offered)
    last, ever = {}, {}
    for t in sel.trials:
        last[t.label] = t
        ever[t.label] = max(ever.get(t.label, -np.inf), t.t)
    dropped = dict(sel.dropped)
    rest, cannot = [], []
    for c in engine.candidates:
        if c.label in taken:
            continue
        eff = c.build(n)
        absorbed = sel.absorbed.get(c.label, 0.0)
        t = last.get(c.label)
        ev = {"diagnosable": True, "label": c.label, "absorbed_fraction": absorbed}
        if t is not None:
            ev.update(cv_rms_with_mm=t.cv_rms_mm, cv_rms_without_mm=t.base_cv_rms_mm, cv_gain=t.gain, cv_gain_t=t.t,
                      cv_rms_by_blocking_mm=t.by_blocking_mm)
        alt = next((o for o in engine.candidates if o.label in sel.offered and alternatives(c, o)), None)
        if alt is not None:
            ev["reason"] = f"the same effect as {alt.label} (taken), which predicted the held-out points better"
        elif c.label in sel.shadowed:
            by, share = sel.shadowed[c.label]
            ev["reason"] = (f"cannot be told from {by}, which is in the model: it explains {100 * share:.0f} % of this "
                            "candidate's signature beyond the geometry (one class)")
        elif c.label in dropped:
            ev["reason"] = (f"taken, then dropped: once the other effects were in, removing it cost only "
                            f"t = {dropped[c.label]:.1f}")
        elif absorbed > opt.absorbed_limit and ever.get(c.label, -np.inf) < 3.0:
            ev.update(diagnosable=False, remedy=REMEDY[c.name],
                      reason=f"{100 * absorbed:.0f} % absorbed by the geometric model")
            cannot.append({"effect": c.name, "label": c.label, "joints": list(eff.joints), "reason": ev["reason"],
                           "remedy": REMEDY[c.name]})
        elif t is not None:
            ev["reason"] = (f"held-out RMS {t.base_cv_rms_mm:.4f} -> {t.cv_rms_mm:.4f} mm (gain {100 * t.gain:+.1f} %, "
                            f"t = {t.t:.1f}): not a significant gain")
        else:
            continue                     # never tried: an alternative (time constant, degree) of a taken effect
        rest.append((np.inf if t is None else t.cv_rms_mm, Finding(c.name, tuple(eff.joints), False, final, final, ev)))
    for u in engine.cannot_tell:
        cannot.append({**u, "remedy": REMEDY[u["effect"]]})
        rest.append((np.inf, Finding(u["effect"], tuple(u["joints"]), False, final, final,
                                     {"diagnosable": False, "reason": u["reason"], "remedy": REMEDY[u["effect"]]})))
    rest.sort(key=lambda x: x[0])
    return [f for _, f in rest], cannot
