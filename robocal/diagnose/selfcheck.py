"""Withheld-effect self-check of the diagnosis: simulate campaigns where effects are present but absent from the
starting model (``robocal.simulation.truth_cell``, written from the physics without the engine), diagnose them, count what was
found.

Kinds of trial (``trial_plan``): one library effect (``single``), none (``control``), two effects (``combo``), an
effect outside the library (``outside``: a sag growing with the reach), and the failure classes of real campaigns
(``FORMS``): compliance + parallel-axis misalignment + a gear term on a small arm measured over a box
(``compound``), compliance sampled sparsely at extreme poses (``sparse``), a drift correlated with J1 through the
measurement order, no timestamps (``order_drift``; ``order_gear``: a J1 gear error measured in J1 order), a
read-back lag with compliance, read-back joints only (``lag_compliance``). ``truth_input`` turns a campaign
into a ``DiagnosisInput`` the way ``campaign diagnose`` reads a CSV (rows in measurement order).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from robocal.measure.approach import approach_signs, moves_from_order
from .records import DiagnosisInput, DiagnosisOptions
from .core import diagnose
from robocal.effects.bases import EFFECT_NAMES
from robocal.measure.noise import TrackerUncertainty, noise_floor_mm
from robocal.measure.repeats import noise_floor_from_repeats as repeat_floor, repeat_dof
from robocal.simulation.truth_cell import LIBRARY_TRUTHS, TruthCampaign, TruthProtocol, simulate, small_arm_nominal

LABELS = ("none",) + EFFECT_NAMES
SMALL_ARM = dict(sampling="box", misalignment_deg=0.05, kg_per_mm=0.02, payloads_kg=(0.0,), timestamps=False,
                 stiffness_nm_per_rad=((6e4, 1.5e5), (3e4, 8e4)), gear_joints=(2, 3), gear_arcsec=90.0)
FORMS = {   # name: (effects, protocol, small arm, what must be named)
    "compound": (("joint_compliance", "gear_cyclic"), SMALL_ARM, True, ("joint_compliance", "gear_cyclic")),
    "sparse": (("joint_compliance",), dict(sampling="sparse_extremes"), False, ("joint_compliance",)),
    "order_drift": (("registration_drift",), dict(order="sweep_j1", timestamps=False), False, ()),
    "order_gear": (("gear_cyclic",), dict(order="sweep_j1", timestamps=False, gear_joints=(1,)), False, ()),
    "lag_compliance": (("readback_lag", "joint_compliance"), {}, False, ("readback_lag", "joint_compliance")),
}
ORDER_FORMS = ("order_drift", "order_gear")


def truth_input(camp: TruthCampaign) -> DiagnosisInput:
    """Calibration and test rows of a truth campaign as ``campaign diagnose`` sees a CSV: read-back joints, rows in
    measurement order (moves and approach directions over all rows), the floor from the repeat burst (grouped by
    the commanded joints)."""
    check = camp.mask("check")
    use = ~check
    q_full = camp.q_read_rad
    move, prev = moves_from_order(q_full)
    floor = repeat_floor(np.degrees(camp.q_cmd_rad[check]), camp.p_mm[check]) if check.any() else None
    source, dof = "repeats", None
    if floor is None:
        floor = noise_floor_mm(camp.p_mm[use], TrackerUncertainty(), camp.protocol.repeatability_rp_mm)
        source = "specs"
    else:
        dof = repeat_dof(np.degrees(camp.q_cmd_rad[check]))
    return DiagnosisInput(camp.nominal, q_full[use], camp.p_mm[use], camp.cov_mm2[use], camp.mask("calib")[use],
                          camp.mask("test")[use], floor, source, dof,
                          t_s=None if camp.t_s is None else camp.t_s[use], payload_kg=camp.payload_kg[use],
                          order=np.flatnonzero(use).astype(float), approach=approach_signs(q_full)[use],
                          move_rad=move[use], prev_move_rad=prev[use])


@dataclass(frozen=True)
class Trial:
    kind: str                        # single | control | combo | outside | a FORMS name
    seed: int
    truths: tuple                    # truth.TruthEffect
    diagnosed: tuple[str, ...]       # accepted effects in selection order
    diagnosed_joints: tuple[tuple[int, ...], ...]
    classes: tuple[tuple[str, ...], ...]   # per accepted effect: itself + its confusable class
    confound: bool                   # an effect and a drift in measurement order are reported as one class
    baseline_test_rms_mm: float
    final_test_rms_mm: float
    noise_floor_mm: float
    unexplained: bool
    shrinkage: tuple[tuple[str, float, float], ...]   # (effect, predicted, achieved) per accepted effect
    seconds: float
    setting: str = ""

    @property
    def truth_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.truths if t.name in EFFECT_NAMES)

    @property
    def acceptable(self) -> set[str]:
        """Names that are not spurious: the truths, the gravity-elastic class for a reach sag, and any pose effect
        reported in one class with the drift it may be (order-correlated forms)."""
        ok = set(self.truth_names)
        if any(t.name == "reach_deflection" for t in self.truths):
            ok |= {"joint_compliance", "payload_deflection"}
        return ok

    @property
    def primary(self) -> str:
        return self.diagnosed[0] if self.diagnosed else "none"

    @property
    def named_right(self) -> bool:
        """Single effects: the first accepted effect is the truth or names it in its class. Forms: every effect
        the form requires is named (accepted or in a class); order forms: the confound class is named."""
        if self.kind in ORDER_FORMS:
            return self.confound
        if self.kind in FORMS:
            named = {n for c in self.classes for n in c}
            return set(FORMS[self.kind][3]) <= named and not self.lag_as_backlash
        return bool(self.truth_names) and bool(self.classes) and self.truth_names[0] in self.classes[0]

    @property
    def lag_as_backlash(self) -> bool:
        """A read-back lag in the truth and backlash accepted though backlash is not."""
        return ("readback_lag" in self.truth_names and "backlash" in self.diagnosed
                and "backlash" not in self.truth_names)

    @property
    def spurious(self) -> int:
        """Accepted effects whose class contains no true effect (and that are no confound class)."""
        truth = self.acceptable
        return sum(1 for c in self.classes if not truth & set(c) and not (self.confound and
                                                                           "registration_drift" in c))

    @property
    def exact(self) -> bool:
        return set(self.diagnosed) == set(self.truth_names) and len(self.diagnosed) == len(set(self.diagnosed))

    @property
    def joints_ok(self) -> bool:
        """Every true effect found; gear, backlash and lag on exactly the true joints."""
        got: dict[str, set] = {}
        for name, js in zip(self.diagnosed, self.diagnosed_joints):
            got.setdefault(name, set()).update(js)
        for t in self.truths:
            if t.name not in EFFECT_NAMES:
                continue
            if t.name not in got:
                return False
            if t.name in ("gear_cyclic", "backlash", "readback_lag") and got[t.name] != set(t.joints):
                return False
        return True

    def to_dict(self) -> dict:
        return {"kind": self.kind, "seed": self.seed, "setting": self.setting,
                "truth": [{"effect": t.name, "joints": list(t.joints), "form": t.form} for t in self.truths],
                "diagnosed": list(self.diagnosed), "diagnosed_joints": [list(j) for j in self.diagnosed_joints],
                "classes": [list(c) for c in self.classes], "confound": self.confound,
                "named_right": self.named_right, "spurious": self.spurious, "exact": self.exact,
                "lag_as_backlash": self.lag_as_backlash, "joints_ok": self.joints_ok if self.truths else None,
                "baseline_test_rms_mm": self.baseline_test_rms_mm, "final_test_rms_mm": self.final_test_rms_mm,
                "noise_floor_mm": self.noise_floor_mm, "unexplained": self.unexplained,
                "shrinkage": [{"effect": e, "predicted_mm": p, "achieved_mm": a} for e, p, a in self.shrinkage],
                "seconds": self.seconds}


def trial_setting(kind: str, effects: Sequence[str], seed: int) -> tuple[TruthProtocol, bool]:
    """(protocol, small arm) of a trial: the form's protocol, else timestamps withheld at random (seeded) in a
    quarter of the campaigns without time effects."""
    if kind in FORMS:
        _, kw, small, _ = FORMS[kind]
        return TruthProtocol(**kw), small
    rng = np.random.default_rng(seed + 77_000)
    timed = any(e in ("thermal_drift", "registration_drift") for e in effects)
    return TruthProtocol(timestamps=timed or rng.random() >= 0.25), False


def run_trial(kind: str, effects: Sequence[str], seed: int, options: DiagnosisOptions = DiagnosisOptions()) -> Trial:
    pr, small = trial_setting(kind, effects, seed)
    camp = simulate(effects, seed, pr, nominal=small_arm_nominal() if small else None)
    t0 = time.perf_counter()
    d = diagnose(truth_input(camp), options)
    secs = time.perf_counter() - t0
    acc = [f for f in d.findings if f.accepted]
    shrink = tuple((f.effect, float(f.evidence["cv_rms_before_mm"] - f.evidence["cv_rms_after_mm"]),
                    float(f.test_rms_before_mm - f.test_rms_after_mm)) for f in acc)
    classes = tuple(tuple([f.effect] + [c["effect"] for c in f.evidence.get("confusable_with", [])]) for f in acc)
    confound = any("order_confound" in f.evidence for f in acc) or any(
        "follow" in u["reason"] and "measurement order" in u["reason"] for u in d.undiagnosable)
    setting = "timestamps" if pr.timestamps else "no timestamps"
    return Trial(kind, seed, camp.truths, tuple(f.effect for f in acc), tuple(tuple(f.joints) for f in acc), classes,
                 confound, d.baseline_test_rms_mm, d.final_test_rms_mm, d.noise_floor_mm, d.unexplained, shrink, secs,
                 setting)


def trial_plan(seeds: int = 5, controls: int | None = None, combos: int | None = None,
               effects: Sequence[str] = LIBRARY_TRUTHS, first_seed: int = 1000, outside: int | None = None,
               forms: Sequence[str] = tuple(FORMS)) -> list[tuple[str, tuple, int]]:
    """(kind, effects, seed) of a self-check: ``seeds`` per effect and per form, controls (default 2 x seeds),
    two-effect combinations (default 2 x seeds, random pairs that are not both elastic) and campaigns with an
    effect outside the library (reach-dependent sag, default seeds)."""
    controls = 2 * seeds if controls is None else controls
    combos = 2 * seeds if combos is None else combos
    outside = seeds if outside is None else outside
    plan, s = [], first_seed
    for name in effects:
        for _ in range(seeds):
            plan.append(("single", (name,), s))
            s += 1
    for _ in range(controls):
        plan.append(("control", (), s))
        s += 1
    rng = np.random.default_rng(first_seed)
    pairs = [(a, b) for i, a in enumerate(effects) for b in effects[i + 1:]
             if {a, b} != {"joint_compliance", "payload_deflection"}]
    for _ in range(combos):
        plan.append(("combo", pairs[int(rng.integers(len(pairs)))], s))
        s += 1
    for _ in range(outside):
        plan.append(("outside", ("reach_deflection",), s))
        s += 1
    for form in forms:
        for _ in range(seeds):
            plan.append((form, FORMS[form][0], s))
            s += 1
    return plan


def _count(ts, attr) -> int:
    return sum(bool(getattr(t, attr)) for t in ts)


@dataclass(frozen=True)
class SelfCheckResult:
    trials: tuple[Trial, ...]
    seconds: float

    def confusion(self) -> dict[str, dict[str, int]]:
        """Single-effect trials and controls: truth -> primary (first accepted) diagnosis -> count."""
        m = {a: {b: 0 for b in LABELS} for a in LABELS}
        for t in self.trials:
            if t.kind in ("single", "control"):
                m[t.truth_names[0] if t.truth_names else "none"][t.primary] += 1
        return m

    def form_table(self) -> dict[str, dict[str, int]]:
        """Per failure-class form (FORMS): trials, named right, confound named, lag accepted as backlash."""
        return {f: {"n": len(ts), "named_right": _count(ts, "named_right"), "confound": _count(ts, "confound"),
                    "lag_as_backlash": _count(ts, "lag_as_backlash"),
                    "diagnosed": [list(t.diagnosed) for t in ts]}
                for f in FORMS if (ts := [t for t in self.trials if t.kind == f])}

    def summary(self) -> dict:
        singles = [t for t in self.trials if t.kind == "single"]
        controls = [t for t in self.trials if t.kind == "control"]
        combos = [t for t in self.trials if t.kind == "combo"]
        outside = [t for t in self.trials if t.kind == "outside"]
        per_effect = {}
        for name in EFFECT_NAMES:
            ts = [t for t in singles if t.truth_names == (name,)]
            if ts:
                per_effect[name] = {"n": len(ts), "named_right": _count(ts, "named_right"),
                                    "primary_correct": sum(t.primary == name for t in ts),
                                    "exact": _count(ts, "exact"), "joints_ok": _count(ts, "joints_ok")}
        tp = sum(len(set(t.diagnosed) & set(t.truth_names)) for t in combos)
        n_true = sum(len(t.truth_names) for t in combos)
        n_diag = sum(len(t.diagnosed) for t in combos)
        errs = [(p - a) for t in self.trials for e, p, a in t.shrinkage if e in t.truth_names]
        achieved = [a for t in self.trials for e, p, a in t.shrinkage if e in t.truth_names]
        n_all = len(self.trials)
        spurious = sum(t.spurious for t in self.trials)
        lag = [t for t in self.trials if "readback_lag" in t.truth_names]
        return {
            "single_trials": len(singles), "named_right": _count(singles, "named_right"),
            "primary_correct": sum(t.primary == t.truth_names[0] for t in singles),
            "exact_set": _count(singles, "exact"), "joints_ok": _count(singles, "joints_ok"),
            "per_effect": per_effect, "forms": self.form_table(),
            "controls": len(controls), "controls_clean": sum(not t.diagnosed for t in controls),
            "controls_unexplained": _count(controls, "unexplained"),
            "combo_trials": len(combos), "combo_exact": _count(combos, "exact"),
            "combo_recall": tp / n_true if n_true else None, "combo_precision": tp / n_diag if n_diag else None,
            "outside_trials": len(outside), "outside_unexplained": _count(outside, "unexplained"),
            "outside_spurious": sum(t.spurious for t in outside),
            "lag_trials": len(lag), "lag_as_backlash": _count(lag, "lag_as_backlash"),
            "datasets": n_all, "spurious_acceptances": spurious,
            "spurious_per_20": 20.0 * spurious / n_all if n_all else None,
            "shrinkage_error_mm": {"n": len(errs), "mean": float(np.mean(errs)) if errs else None,
                                   "mean_abs": float(np.mean(np.abs(errs))) if errs else None,
                                   "max_abs": float(np.max(np.abs(errs))) if errs else None,
                                   "mean_achieved": float(np.mean(achieved)) if achieved else None},
            "seconds_per_trial": float(np.mean([t.seconds for t in self.trials])) if self.trials else None,
            "seconds": self.seconds,
        }

    def passed(self) -> bool:
        """Done-when: every single effect and every form named right in >= 95 % of its trials, nothing accepted on
        the controls, the confound class named in every order-correlated trial, a lag never called backlash."""
        s = self.summary()
        groups = list(s["per_effect"].values()) + list(s["forms"].values())
        return (s["single_trials"] > 0 and all(g["named_right"] >= 0.95 * g["n"] for g in groups)
                and s["controls_clean"] == s["controls"] and s["lag_as_backlash"] == 0
                and all(s["forms"][f]["confound"] == s["forms"][f]["n"] for f in ORDER_FORMS if f in s["forms"]))

    def to_dict(self) -> dict:
        return {"summary": self.summary(), "confusion": self.confusion(), "labels": list(LABELS),
                "trials": [t.to_dict() for t in self.trials], "passed": self.passed()}


def run_self_check(seeds: int = 5, controls: int | None = None, combos: int | None = None,
                   options: DiagnosisOptions = DiagnosisOptions(), outside: int | None = None,
                   progress: Callable[[int, int, Trial], None] | None = None,
                   forms: Sequence[str] = tuple(FORMS), first_seed: int = 1000) -> SelfCheckResult:
    """Run the whole withheld-effect self-check (see ``trial_plan``) on truth campaigns."""
    plan = trial_plan(seeds, controls, combos, first_seed=first_seed, outside=outside, forms=forms)
    t0 = time.perf_counter()
    trials = []
    for i, (kind, effects, seed) in enumerate(plan):
        trials.append(run_trial(kind, effects, seed, options))
        if progress:
            progress(i + 1, len(plan), trials[-1])
    return SelfCheckResult(tuple(trials), time.perf_counter() - t0)


SHORT = {"none": "none", "joint_compliance": "comp", "payload_deflection": "pay", "gear_cyclic": "cyc",
         "backlash": "back", "readback_lag": "lag", "thermal_drift": "therm", "axis_coupling": "coup",
         "registration_drift": "tdrift"}


def format_confusion(result: SelfCheckResult) -> str:
    """Plain-text confusion matrix (truth rows x primary diagnosis columns) with short labels, then one line per
    failure-class form."""
    m = result.confusion()
    lines = ["truth \\ diagnosed | " + " | ".join(SHORT[b] for b in LABELS)]
    for a in LABELS:
        if sum(m[a].values()):
            lines.append(f"{SHORT[a]} | " + " | ".join(str(m[a][b]) if m[a][b] else "." for b in LABELS))
    for f, v in result.form_table().items():
        lines.append(f"{f} | named right {v['named_right']}/{v['n']}, confound class named {v['confound']}/{v['n']}"
                     f", lag called backlash {v['lag_as_backlash']}")
    return "\n".join(lines)
