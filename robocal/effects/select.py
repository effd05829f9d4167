"""Which effects the data support: forward selection by blocked cross-validation around the geometric solution.

Every round tries each remaining candidate on top of the geometry + the effects taken so far (linearised at the
geometric solution) and takes the one with the lowest held-out error, if its gain is significant: one-sided paired t
of the per-point squared errors > 3 and held-out RMS lower by > 2 % (``robocal.measure.stats.paired_gain``), or >
10 % lower with t > 2 or a one-sided signed-rank z > 2 (``signed_rank_z``: a gain over most poses that a few far
poses' large differences hide from the t), the per-point errors being the mean over the blockings (pose blocks and,
when the measurement order is known, order blocks), and the gain positive under each blocking on its own. An effect
just taken loses the parts the data do not need (a joint, a harmonic, a memory term: removing the part must cost
t >= 2, or pass the rank rule); refinements of it
(compliance's free mass distribution; once that is taken, the links' complete gravity regressor) join the candidates. A joint's cyclic errors of a higher order (an encoder's
track, a gear's teeth: two periods over the joint's span up to 40 per revolution) are one candidate per joint, a
scan: in every fold the order that fits the training rows best predicts the held-out rows, so the pick among many
orders is cross-validated too (nested); the order taken is the one that fits all rows best. At the end every taken
effect's parts are judged again from the effect as offered, given all the others (a part pruned while a larger
effect was unmodelled comes back); then every taken effect must still be needed given the others (removing it costs
t >= 2 and >= 1 % of RMS, or passes the rank rule), else it is dropped, and the parts are pruned once more. When
that path ends with compliance's lever form and not the links' form, a second path offers the links' form in place
of the lever form, and is kept when its final held-out RMS is lower by more than 2 % (the forward steps' order
decides what else shows: at few rows a gear or a drift may pass beside the links' form and not beside the lever
form).
Held-out prediction is the arbiter: plausibility only picks among candidates that predict equally well (a plausible
one before an implausible best), and never drops an effect; consistency is reported, never used here.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .bases import effect_regressor, meta_rows
from robocal.identify.whitened import whitening
from robocal.kinematics.models import JACOBIAN_ROWS, Kinematics, identification_jacobian
from robocal.measure.stats import paired_gain, signed_rank_z
from .cv import BlockedCV, Blocking, order_blocks, pose_blocks
from .library import parts, refinement_closure, refinements
from .model import EffectChoice

TAKE_T, TAKE_GAIN = 3.0, 0.02      # an effect is taken on a paired t > 3 and a held-out RMS gain > 2 % ...
LARGE_T, LARGE_GAIN = 2.0, 0.10    # ... or on t > 2 with a gain > 10 % (a gain concentrated on few poses has a
#                                    heavy-tailed per-point difference: its t understates how unlikely it is)
REPRUNE_FROM_OFFERED = True   # before the final check, every taken effect's parts are judged again from the effect
#                               as offered, given all the others (issue 32, tenth protocol: kept)
RANK_Z = 2.0    # ... or, with a gain > 10 %, on a signed-rank z > 2 (the large-gain rule's level, read from the ranks:
#                 a gain over most poses that a few far poses' large differences hide from the t); None: t alone.
#                 The same evidence keeps a part or an effect (issue 32, seventh protocol)
SHADOW_SHARE = 0.9      # a candidate whose visible part (beyond the geometry) lies >= 90 % inside a taken effect's
#                         span cannot be told from that effect: one class
SHADOW_MIN_VISIBLE = 0.01   # (judged only when at least 1 % of the candidate is visible beyond the geometry)
KEEP_T = 2.0            # a part or an effect stays when removing it costs at least this paired t ...
KEEP_GAIN = 0.005       # ... and this share of the held-out RMS (parts; effects: 2 x)
F_LEVEL = None     # with a level (e.g. 0.01): an effect or a part is also taken / kept on in-sample evidence, a
#                    nested F-test of the whitened rows (``BlockedCV.nested_p``: p below F_LEVEL / the number of
#                    candidates) with a held-out gain > TAKE_GAIN under every blocking; None: held-out evidence alone
#                    (issue 32's seventeenth and eighteenth protocols did not keep it)
F_PARTS = True     # the in-sample evidence keeps a part of a taken effect too (False: parts are pruned on held-out
#                    evidence alone; the rule takes and keeps whole effects)
SHORT_ROWS = None  # with a row count (e.g. 100): a selection over fewer rows cross-validates with at least
SHORT_FOLDS = 10   # this many folds (each fit sees 90 % of the rows, not 80 %); None: the folds asked for (issue
#                    32's nineteenth protocol did not keep 100: bench/bench_short_folds.py)
LINKS_PATH_GAIN = 0.02  # when the selection takes gravity compliance's lever form and not the links' form, it is
#                         run again with the links' form offered in place of the lever form, and that path is kept
#                         when its final held-out RMS is lower by more than this share (None: one path). The links'
#                         form after the lever form must gain over it in the model; at few rows the effects taken
#                         after it (a gear, a drift) may only show beside the links' form (issue 32, twentieth
#                         protocol, bench/bench_links_path.py: kept, mean ratio 0.996, none worse)
F_RANK_TOL = 1e-6  # eigenvalue of a candidate's unit-norm columns beyond the others', below which it adds no rank
BLOCK_VALUES = 1 << 19  # rows x columns of the design per block (the scan's hundreds of columns: fewer rows)


@dataclass(frozen=True)
class Trial:
    """One candidate tried in one round: held-out RMS (mm, mean over the blockings and per blocking) against the
    model so far, relative gain, paired t, whether it was taken; ``candidate`` the candidate it was tried as (a scan
    family's label for the member the scan picked; else ``label``)."""
    round: int
    label: str
    cv_rms_mm: float
    by_blocking_mm: dict
    base_cv_rms_mm: float
    gain: float
    t: float
    taken: bool
    candidate: str = ""

    def to_dict(self) -> dict:
        return {"round": self.round, "effect": self.label, "candidate": self.candidate or self.label,
                "cv_rms_mm": self.cv_rms_mm, "cv_rms_by_blocking_mm": self.by_blocking_mm,
                "base_cv_rms_mm": self.base_cv_rms_mm, "gain": self.gain, "t": self.t, "taken": self.taken}


@dataclass(eq=False)
class Step:
    """A taken effect: the round, held-out RMS before/after (mean and per blocking), the rivals that predicted
    as well (paired t of the winner over them < 2) and the parts pruned."""
    choice: EffectChoice
    round: int
    before_mm: float
    after_mm: float
    by_blocking_mm: dict
    t: float
    gain: float
    rivals: list = field(default_factory=list)      # [(label, name, cv_rms_mm, t_winner_over_it)]
    pruned: list = field(default_factory=list)      # [(part label, t of removing it)]
    note: str = ""                                  # why it was taken before a slightly better predictor

    def to_dict(self) -> dict:
        return {"effect": self.choice.label, "name": self.choice.name, "round": self.round,
                "cv_rms_before_mm": self.before_mm, "cv_rms_after_mm": self.after_mm,
                "cv_rms_by_blocking_mm": self.by_blocking_mm, "t": self.t, "gain": self.gain,
                "rivals": [{"effect": lb, "name": nm, "cv_rms_mm": r, "t_over": t} for lb, nm, r, t in self.rivals],
                "pruned": [{"part": lb, "t": t} for lb, t in self.pruned], "note": self.note}


@dataclass(frozen=True, eq=False)
class EffectSelection:
    taken: tuple[EffectChoice, ...]
    steps: tuple[Step, ...]
    trials: tuple[Trial, ...]
    dropped: tuple[tuple[str, float], ...]     # (label, t of removing it) dropped in the final check
    geometric_cv_rms_mm: float
    final_cv_rms_mm: float
    folds: int
    blockings: tuple[str, ...]
    candidates: tuple[str, ...]
    absorbed: dict = field(default_factory=dict)     # label -> share of the candidate inside the geometry's span
    offered: tuple[str, ...] = ()                    # per taken effect: the candidate it was offered as (unpruned)
    shadowed: dict = field(default_factory=dict)     # label -> (taken label, share of the candidate's visible part
    #                                                  inside the taken effect's span): one class with it
    rows: tuple[int, int] = (0, 0)                   # (rows cross-validated, calibration rows): a seeded subset when
    #                                                  fewer
    path: str = ""                                   # the two paths compared (``LINKS_PATH_GAIN``), when they were

    def to_dict(self) -> dict:
        sub = self.rows[0] < self.rows[1]
        return {"method": f"forward selection, {self.folds}-fold cross-validation blocked by "
                          f"{' and by '.join(self.blockings)} (linearised at the geometric solution); an effect is "
                          "taken when the paired t of the per-point held-out squared errors exceeds 3 and the "
                          "held-out RMS drops by more than 2 % (or by more than 10 % with t > 2 or a signed-rank "
                          "z > 2), under every blocking; "
                          "a joint's cyclic errors of higher orders are one candidate, its order chosen inside "
                          "every fold (nested)" + (f"; on a seeded subset of {self.rows[0]} of the {self.rows[1]} "
                                                   "calibration rows (the taken effects are fitted on all)" if sub
                                                   else ""),
                **({"rows": self.rows[0], "of_rows": self.rows[1]} if sub else {}),
                "taken": [c.label for c in self.taken], "geometric_cv_rms_mm": self.geometric_cv_rms_mm,
                "final_cv_rms_mm": self.final_cv_rms_mm, "blockings": list(self.blockings),
                "candidates": list(self.candidates), "steps": [s.to_dict() for s in self.steps],
                "dropped": [{"effect": lb, "t": t} for lb, t in self.dropped], "absorbed_by_geometry": self.absorbed,
                "shadowed": {k: {"by": v[0], "share": v[1]} for k, v in self.shadowed.items()},
                "trials": [t.to_dict() for t in self.trials], **({"path": self.path} if self.path else {})}


class _Design:
    """Column blocks of the linearised design: the identified geometry and every candidate (and refinement).
    ``blocks()`` computes the design (N, 3, P) and the residuals of the geometric solution row block by row block
    (``BlockedCV.of_blocks`` keeps it whitened, in float32)."""

    def __init__(self, kin, geo_cols, q, p_meas, meta, choices):
        self._args = (kin, np.asarray(geo_cols, int), q, p_meas, meta, [c.build(kin.n) for c in choices])
        self.cols: dict[EffectChoice, np.ndarray] = {}
        self.names: dict[EffectChoice, tuple[str, ...]] = {}
        at = len(geo_cols)
        self.geo = np.arange(at)
        for c, eff in zip(choices, self._args[5]):
            self.cols[c] = np.arange(at, at + eff.k)
            self.names[c] = eff.param_names
            at += eff.k
        self.P = at

    def blocks(self):
        """(rows slice, A_b (b, 3, P), measured - geometric model (b, 3) mm) of consecutive row blocks."""
        kin, geo_cols, q, p_meas, meta, built = self._args
        G = len(geo_cols)
        rows = int(np.clip(BLOCK_VALUES // self.P, 256, JACOBIAN_ROWS))     # blocks of ~12 MB whatever the columns
        for s in range(0, len(q), rows):                     # row blocks: no Jacobian or basis of every row
            b = slice(s, min(s + rows, len(q)))
            p, J = identification_jacobian(kin, q[b])
            A = np.empty((len(p), 3, self.P))
            A[:, :, :G] = J[:, :, geo_cols]
            at, mb = G, meta_rows(meta, b)
            for eff in built:
                A[:, :, at:at + eff.k] = effect_regressor(kin, q[b], mb, eff, jacobian=(p, J))
                at += eff.k
            yield b, A, p_meas[b] - p

    def sub(self, full: EffectChoice, reduced: EffectChoice, n: int) -> np.ndarray:
        """Columns of ``reduced`` (a part of ``full`` removed) among ``full``'s columns."""
        keep = set(reduced.build(n).param_names)
        return np.array([c for c, nm in zip(self.cols[full], self.names[full]) if nm in keep], int)


def _mean(se: dict) -> np.ndarray:
    return np.mean(np.stack(list(se.values())), axis=0)


def _rms(se) -> float:
    return float(np.sqrt(np.mean(se)))


def select_effects(kin: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
                   cov_mm2: np.ndarray | None, meta, candidates, folds: int = 5, seed: int = 0,
                   max_effects: int = 6, plausible=None, scans=(), of_rows: int | None = None) -> EffectSelection:
    """The forward selection (``_forward``, see the module docstring); with ``LINKS_PATH_GAIN``, also the path with
    the links' form offered in place of the lever form, when the first one takes the lever form alone."""
    args = (kin, geo_cols, q_rad, p_tracker_mm, cov_mm2, meta, candidates, folds, seed, max_effects, plausible,
            scans, of_rows)
    sel = _forward(*args)
    forms = _forms(sel.taken)
    if LINKS_PATH_GAIN is None or "levers" not in forms or "links" in forms:
        return sel
    alt = _forward(*args, refined_forms=("links",))
    keep = alt.final_cv_rms_mm < (1.0 - LINKS_PATH_GAIN) * sel.final_cv_rms_mm
    path = (f"the links' form offered in place of the lever form: final held-out RMS {alt.final_cv_rms_mm:.4f} mm, "
            f"the lever form's path {sel.final_cv_rms_mm:.4f} mm; kept the "
            + ("links' path" if keep else "lever form's path") + f" (it must be lower by > {LINKS_PATH_GAIN:.0%})")
    return replace(alt if keep else sel, path=path)


def _forms(taken) -> set:
    """The forms of gravity compliance among the taken effects."""
    return {dict(c.options).get("form", "gravity") for c in taken if c.name == "joint_compliance"}


def _forward(kin: Kinematics, geo_cols: np.ndarray, q_rad: np.ndarray, p_tracker_mm: np.ndarray,
             cov_mm2: np.ndarray | None, meta, candidates, folds: int = 5, seed: int = 0,
             max_effects: int = 6, plausible=None, scans=(), of_rows: int | None = None,
             refined_forms=None) -> EffectSelection:
    """Forward selection (see the module docstring) around the geometric solution ``kin`` with identified
    columns ``geo_cols``; ``meta["order"]`` (the measurement order) adds the order blocking. ``plausible(choice,
    values) -> bool`` (the physical range): among candidates that predict equally well (the best one's paired t
    over them < 2) a plausible one is preferred to an implausible best. ``scans``: families of alternatives
    (``library.scan_families``: one joint's cyclic errors of every higher order); each family is one candidate
    per round, its member chosen inside every fold of the cross-validation (nested: the scan's pick among many
    orders does not make its held-out errors optimistic) and, to be taken, on all rows. ``of_rows``: the rows these
    are a subset of (reported). ``refined_forms``: the forms offered once gravity compliance is taken (None: the
    library's)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    n = kin.n
    folds = short_folds(folds, len(q))
    pool = list(dict.fromkeys(candidates))
    extra = refinement_closure(pool, n)
    families = [tuple(f) for f in scans if len(f)]
    design = _Design(kin, geo_cols, q, np.asarray(p_tracker_mm, float), meta,
                     pool + extra + [c for f in families for c in f if c not in pool + extra])
    blockings = [Blocking("pose blocks", pose_blocks(q, folds, seed))]
    if meta.get("order") is not None:
        blockings.append(Blocking("order blocks", order_blocks(meta["order"], folds)))
    W = whitening(cov_mm2, len(q))
    W = np.broadcast_to(np.eye(3), (len(q), 3, 3)) if W is None else W
    cv = BlockedCV.of_blocks(design.blocks(), len(q), design.P, W, blockings)
    ftest = _FTest(cv, F_LEVEL, len(pool) + len(extra))
    model: list[tuple[EffectChoice, np.ndarray, EffectChoice]] = []   # taken (choice, its columns, as offered)

    def errors(entries, extra_cols=()):
        return cv.squared_errors(np.concatenate([design.geo] + [e[1] for e in entries] + [np.asarray(extra_cols, int)]))

    base = errors(model)
    geo_rms = _rms(_mean(base))
    trials, steps = [], []
    for rnd in range(1, max_effects + 1):
        scored = []
        tried = [(c, c.label, errors(model, design.cols[c])) for c in pool]
        in_model = np.concatenate([design.geo] + [e[1] for e in model])
        for family in families:
            live = [c for c in family if not any(c in (e[0], e[2]) for e in model)]
            if live:
                alts = [design.cols[c] for c in live]
                tried.append((live[cv.scan_pick(in_model, alts)], _family_label(family),
                              {b.name: np.sum(cv.scan_errors(in_model, alts, i) ** 2, axis=1)
                               for i, b in enumerate(cv.blockings)}))
        for c, as_candidate, se in tried:
            g = paired_gain(_mean(base), _mean(se))
            each = all(_rms(se[b]) < _rms(base[b]) for b in se)
            trials.append(Trial(rnd, c.label, g.rms_cand_mm, {b: _rms(v) for b, v in se.items()}, g.rms_base_mm,
                                g.gain, g.t, False, as_candidate))
            in_sample = as_candidate == c.label and ftest.passes(g, in_model, design.cols[c])   # not a scan's pick
            if (_supported(g, _mean(base), _mean(se)) or in_sample) and each:
                scored.append((g.rms_cand_mm, len(trials) - 1, c, se, g))
        if not scored:
            break
        scored.sort(key=lambda s: (s[0], s[1]))
        pick = _plausible_pick(scored, cv, design, model, plausible) if plausible else 0
        note = "" if pick == 0 else (f"taken before {scored[0][2].label} (held-out RMS {scored[0][0]:.4f} mm, as "
                                     "good): its values are outside their physical range")
        scored.insert(0, scored.pop(pick))
        _, i, c, se, g = scored[0]
        trials[i] = Trial(**{**trials[i].__dict__, "taken": True})
        rivals = [(o.label, o.name, r, paired_gain(_mean(s), _mean(se)).t) for r, _, o, s, _ in scored[1:]]
        step = Step(c, rnd, g.rms_base_mm, g.rms_cand_mm, {b: _rms(v) for b, v in se.items()}, g.t, g.gain,
                    [rv for rv in rivals if rv[3] < KEEP_T], note=note)
        pool = [o for o in pool if not alternatives(o, c)]
        reduced, base = _prune(errors, design, model, c, c, step, n, ftest)
        model.append((reduced, design.sub(c, reduced, n), c))
        step.choice = reduced
        steps.append(step)
        pool += [r for r in refinements(c, n, refined_forms) if r in design.cols and r not in pool]
    if REPRUNE_FROM_OFFERED:
        _reprune(errors, design, model, steps, n, True, ftest)
    dropped = _final_check(errors, model, steps, design, ftest)
    _reprune(errors, design, model, steps, n, False, ftest)
    absorbed = {c.label: cv.absorbed(design.cols[c], design.geo) for c in candidates}
    shadowed = {}
    for c in candidates:
        if any(c is e[2] or c.label == e[0].label for e in model):
            continue
        for taken, cols, _ in model:
            share = cv.absorbed(design.cols[c], np.concatenate([design.geo, cols]))
            geo = absorbed[c.label]
            visible = (share - geo) / max(1.0 - geo, 1e-12)      # of what the geometry leaves visible
            if visible >= SHADOW_SHARE and 1.0 - geo >= SHADOW_MIN_VISIBLE:
                shadowed[c.label] = (taken.label, visible)
                break
    return EffectSelection(tuple(e[0] for e in model), tuple(steps), tuple(trials), tuple(dropped), geo_rms,
                           _rms(_mean(errors(model))), folds, tuple(b.name for b in blockings),
                           tuple(c.label for c in candidates) + tuple(_family_label(f) for f in families), absorbed,
                           tuple(e[2].label for e in model), shadowed, (len(q), of_rows or len(q)))


def short_folds(folds: int, rows: int) -> int:
    """The folds of a selection over ``rows`` rows: at least ``SHORT_FOLDS`` below ``SHORT_ROWS`` rows."""
    return max(folds, SHORT_FOLDS) if SHORT_ROWS is not None and rows < SHORT_ROWS else folds


class _FTest:
    """The in-sample rule (``F_LEVEL``): a column set is supported when a nested F-test on all rows
    (``BlockedCV.nested_p``) gives p below the level over the number of candidates, with a held-out gain."""

    def __init__(self, cv: BlockedCV, level: float | None, tests: int):
        self.cv, self.alpha = cv, None if level is None else level / max(tests, 1)

    def passes(self, g, base, extra) -> bool:
        """p < the level per test for ``extra`` beyond ``base``, with a held-out gain ``g`` > TAKE_GAIN."""
        return self.alpha is not None and g.gain > TAKE_GAIN and self.cv.nested_p(base, extra, F_RANK_TOL) < self.alpha


def _family_label(family) -> str:
    """``gear_cyclic(J1 h9-40)``: a scan family by its joint and range of orders."""
    hs = [h for c in family for h in dict(c.options)["harmonics"]]
    return family[0].with_options(harmonics=(min(hs),)).label.replace(f"h{min(hs)}", f"h{min(hs)}-{max(hs)}")


def _plausible_pick(scored, cv, design, model, plausible) -> int:
    """Index of the candidate to take: the best held-out one, unless its values are outside their physical range
    and another that predicts as well (the best one's paired t over it < KEEP_T) is inside."""
    def values(c):
        cols = np.concatenate([design.geo] + [e[1] for e in model] + [design.cols[c]])
        return cv.fit(cols)[-len(design.cols[c]):]
    best = scored[0]
    if plausible(best[2], values(best[2])):
        return 0
    for k, s in enumerate(scored[1:], start=1):
        if paired_gain(_mean(s[3]), _mean(best[3])).t < KEEP_T and plausible(s[2], values(s[2])):
            return k
    return 0


def _supported(g, se_base, se_cand) -> bool:
    """Whether the gain ``g`` of the candidate's per-point errors ``se_cand`` over ``se_base`` takes it."""
    return (g.t > TAKE_T and g.gain > TAKE_GAIN) or (g.t > LARGE_T and g.gain > LARGE_GAIN) or _by_ranks(
        g, se_base, se_cand)


def _by_ranks(g, se_base, se_cand) -> bool:
    """A gain above LARGE_GAIN whose signed ranks pass RANK_Z (when the rule is on)."""
    return RANK_Z is not None and g.gain > LARGE_GAIN and signed_rank_z(se_base, se_cand) > RANK_Z


def _needed(g, se_without, se_with, min_gain, in_sample=False) -> bool:
    """Whether removing a part or an effect costs enough: t >= KEEP_T and ``min_gain``, or the rank rule, or the
    in-sample evidence that would take it (``in_sample``: ``_FTest.passes``)."""
    return (g.t >= KEEP_T and g.gain >= min_gain) or _by_ranks(g, se_without, se_with) or in_sample


def alternatives(a: EffectChoice, b: EffectChoice) -> bool:
    """Two candidates for the same physical effect (another warm-up time constant, another drift degree, the
    same joint's effect; for a cyclic error, the same joint and a common order): once one is taken the other is no
    longer tried (refinements are)."""
    if a.name != b.name:
        return False
    if a.name in ("thermal_drift", "registration_drift"):
        return True
    oa, ob = dict(a.options), dict(b.options)
    if a.name == "gear_cyclic" and not set(oa.get("harmonics", (1, 2))) & set(ob.get("harmonics", (1, 2))):
        return False                     # other orders of the same joint's cyclic error: a low and a high one
    return oa.get("joint") == ob.get("joint")


def _cols(design, model, extra=()) -> np.ndarray:
    """Columns of the geometry, the taken effects ``model`` and ``extra``."""
    return np.concatenate([design.geo] + [e[1] for e in model] + [np.asarray(extra, int)])


def _prune(errors, design, model, choice, full, step, n, ftest):
    """``choice`` (a part of the offered ``full``) without the parts whose removal costs less than KEEP_T /
    KEEP_GAIN given the other effects ``model`` (the cheapest first, until every part left is needed). Returns
    (the pruned choice, the per-point errors of the model with it)."""
    se = errors(model, design.sub(full, choice, n))
    while True:
        best = None
        for label, reduced in parts(choice):
            kept = design.sub(full, reduced, n)
            s = errors(model, kept)
            g = paired_gain(_mean(s), _mean(se))             # what keeping the part gains
            part = np.setdiff1d(design.sub(full, choice, n), kept)
            if not _needed(g, _mean(s), _mean(se), KEEP_GAIN, F_PARTS and ftest.passes(
                    g, _cols(design, model, kept), part)) \
                    and (best is None or g.t < best[0]):
                best = (g.t, label, reduced, s)
        if best is None:
            return choice, se
        t, label, choice, se = best
        step.pruned.append((label, t))


def _reprune(errors, design, model, steps, n, from_offered: bool, ftest) -> None:
    """Every taken effect's parts judged again given all the others (in place): from the effect as offered (a part
    pruned while a larger effect was still unmodelled comes back when it is needed), or from its pruned state (the
    parts the later effects made unnecessary)."""
    for i, (c, _, full) in enumerate(model):
        step = next(s for s in steps if s.choice is c)
        if from_offered:
            step.pruned.clear()
        reduced, _ = _prune(errors, design, model[:i] + model[i + 1:], full if from_offered else c, full, step, n,
                            ftest)
        model[i] = (reduced, design.sub(full, reduced, n), full)
        step.choice = reduced


def _final_check(errors, model, steps, design, ftest) -> list[tuple[str, float]]:
    """Drop taken effects that the others made unnecessary (removing one costs t < KEEP_T or < 2 KEEP_GAIN),
    the cheapest first, until every one left is needed."""
    dropped = []
    while len(model) > 1:
        se = errors(model)
        worst = None
        for i in range(len(model)):
            others = model[:i] + model[i + 1:]
            without = _mean(errors(others))
            g = paired_gain(without, _mean(se))
            in_sample = ftest.passes(g, _cols(design, others), model[i][1])
            if not _needed(g, without, _mean(se), 2 * KEEP_GAIN, in_sample) and (worst is None or g.t < worst[0]):
                worst = (g.t, i)
        if worst is None:
            break
        c = model.pop(worst[1])[0]
        dropped.append((c.label, worst[0]))
        steps[:] = [s for s in steps if s.choice is not c]
    return dropped
