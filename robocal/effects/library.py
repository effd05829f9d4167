"""The candidates the engine tries on a dataset, what the data cannot tell, the parts of an effect that can be
pruned, and the physical reading of fitted values against their physical range.

Every candidate is an ``EffectChoice`` of a ``robocal.effects`` factory, so whatever the selection takes is a
parameter of the calibrated model (model.json). Gravity enters through the one ``GravityModel``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from robocal.kinematics.gravity import GravityModel, gravity_torques
from robocal.kinematics.chains import wrist_joints
from robocal.kinematics.models import Kinematics, smr_base
from .model import EffectChoice

ARCMIN = math.pi / 180.0 / 60.0
SINGLE_HARMONICS = False  # True: a joint's low harmonics are also offered one at a time beside the set (a taken one
#                           makes the set and the singles of its order alternatives). Not kept: issue 32, sixteenth
#                           protocol, bench/bench_single_harmonics.py (111 figures mean 1.0002, self-check 9 spurious
#                           acceptances against 8)


@dataclass(frozen=True)
class LibraryOptions:
    """When the data can reveal an effect, and the physical ranges of fitted values."""
    gear_min_span_deg: float = 20.0       # a joint covering less cannot show a cyclic error
    harmonics: tuple[int, ...] = (1, 2, 3, 4)
    degrees_per_harmonic: float = 45.0    # a joint covering S degrees is offered the first S / 45 harmonics (1-4):
    #                                       over a narrow range more harmonics only add polynomial terms
    scan_max_order: int = 40              # cyclic errors of a higher order (an encoder's track, a gear's teeth):
    scan_min_periods: float = 2.0         # each joint is scanned over the orders with at least 2 periods over its
    #                                       span (fewer look like a polynomial) up to 40 per revolution
    scan_points_per_period: float = 4.0   # and at most the order whose period holds 4 of the joint's distinct values
    #                                       on average: sparser, a high order aliases to a low one at the measured
    #                                       poses, which cross-validation on those poses cannot see
    scan_max_rows: int = 20_000           # the scan's columns (N x 3 x 2 per order) are kept up to this many rows
    backlash_min_side: int = 5            # approaches from each side needed on a joint, at least ...
    backlash_min_side_fraction: float = 0.05   # ... and this share of the rows
    lag_min_move_std_deg: float = 1.0     # joints whose moves vary less cannot show a read-back lag
    time_min_span_s: float = 900.0        # timestamps must span this much to profile a drift or warm-up
    temp_min_span_c: float = 0.2
    warmup_tau_s: tuple[float, ...] = (1800.0, 3600.0, 7200.0)
    min_order_points: int = 40            # a drift in measurement order needs this many points
    clock_place_max_r2: float | None = 0.9   # a drift needs a clock the place does not explain: a quadratic in the
    #                                       SMR position fits at most this share of its variance (a serpentine
    #                                       grid's order 0.98-0.99, random order < 0.2); None: no such check
    # physical ranges (a fitted value outside is reported as the best available description, never dropped)
    stiffness_range_nm_per_rad: tuple[float, float] = (1e3, 1e8)
    max_deflection_arcmin: float = 30.0   # compliance: joint deflection over the data
    max_gear_arcsec: float = 120.0        # amplitude of one harmonic
    max_backlash_arcmin: float = 5.0      # half-width
    max_lag: float = 5e-3                 # read-back lag, rad per rad of move
    max_growth: float = 1e-3              # thermal length growth
    max_zero_drift_arcmin: float = 7.0
    max_coupling: float = 0.02
    max_drift_mm: float = 1.0             # registration drift over the run: translation ...
    max_drift_rad: float = 5e-4           # ... and rotation


def main_axes(n: int) -> int:
    """How many joints carry the arm before its wrist: the first n - 3 of an arm of six or more joints (J1-J3 of a
    6-axis arm, J1-J4 of a 7-axis arm), all but the last of a shorter one."""
    return n - 3 if n >= 6 else n - 1


def loaded_joints(kin: Kinematics, q_rad: np.ndarray, gravity: GravityModel, payload) -> tuple[int, ...]:
    """Main-axis joints (``main_axes``: J1-J3 of a 6-axis arm) whose gravity torque varies over the data (> 5 % of
    the largest spread)."""
    gravity = gravity.sized(kin.n)
    tau = gravity_torques(kin, q_rad, gravity.link_masses_kg, payload, gravity.payload_cog_flange_mm,
                          gravity.gravity_base)
    spread = tau.std(axis=0)
    if spread.max() <= 0:
        return ()
    return tuple(int(j) + 1 for j in np.flatnonzero(spread > 0.05 * spread.max()) if j < main_axes(kin.n))


def _payload(meta: Mapping, n: int) -> np.ndarray:
    p = meta.get("payload_kg")
    return np.zeros(n) if p is None else np.asarray(p, float)


def _varies(values: np.ndarray, min_share: float = 0.05) -> bool:
    """At least two distinct values, the rarer ones on >= ``min_share`` of the rows."""
    _, counts = np.unique(np.round(values, 3), return_counts=True)
    return len(counts) >= 2 and np.sort(counts)[-2] >= min_share * len(values)


def candidates(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, gravity: GravityModel,
               opt: LibraryOptions = LibraryOptions()) -> tuple[list[EffectChoice], list[dict]]:
    """(candidates, cannot_tell): the effects these data can reveal as ``EffectChoice`` s, and for the others
    {"effect", "joints", "reason"}."""
    q = np.atleast_2d(q_rad)
    N, n = q.shape
    gravity = gravity.sized(n)
    g = gravity.options()
    out, cannot = [], []
    pay = _payload(meta, N)
    loaded = loaded_joints(kin, q, gravity, pay)
    if loaded:
        out.append(EffectChoice("joint_compliance", (("joints", loaded),) + g))
    else:
        cannot.append({"effect": "joint_compliance", "joints": [2, 3],
                       "reason": "the gravity torque of the main axes does not vary over the poses"})
    if _varies(pay) and loaded:
        out.append(EffectChoice("payload_deflection", (("joints", loaded),) + g[1:]))
    else:
        cannot.append({"effect": "payload_deflection", "joints": list(loaded or (2, 3)),
                       "reason": "one payload only: a payload-dependent deflection cannot be told from the link "
                                 "masses' compliance and the geometry" if meta.get("payload_kg") is not None
                       else "no payload logged: a payload-dependent deflection cannot be told from geometry"})
    for j in range(1 + kin.n_track, n + 1):          # a track has no turn for a cyclic error
        span = math.degrees(float(np.ptp(q[:, j - 1])))
        if span >= opt.gear_min_span_deg:
            k = int(np.clip(span // opt.degrees_per_harmonic, 1, len(opt.harmonics)))
            out.append(EffectChoice("gear_cyclic", (("joint", j), ("harmonics", opt.harmonics[:k]))))
            if SINGLE_HARMONICS and k > 1:
                out += [EffectChoice("gear_cyclic", (("joint", j), ("harmonics", (h,)))) for h in opt.harmonics[:k]]
        else:
            cannot.append({"effect": "gear_cyclic", "joints": [j],
                           "reason": f"J{j} covers only {span:.0f} deg: a cyclic error cannot be told from its zero"})
    out += _backlash(meta, N, n, opt, cannot)
    out += _lag(meta, n, opt, cannot)
    out += _time(meta, N, opt, cannot, tuple(j + kin.n_track for j in (1, 2, 3)), lambda: smr_base(kin, q))
    out += _coupling(kin, q, cannot)
    out += _track(kin, q, cannot)
    return out, cannot


def _track(kin: Kinematics, q: np.ndarray, cannot: list, degrees=(2, 3)) -> list[EffectChoice]:
    """Straightness/flatness of a track's rails, of each degree the spread of carriage positions can show (at least
    degree + 2 distinct positions, so that a polynomial of that degree leaves some freedom); none without a track."""
    if kin.track is None:
        return []
    distinct = len(np.unique(np.round(np.degrees(q[:, 0]), 1)))
    out = [EffectChoice("track_straightness", (("degree", d),)) for d in degrees if distinct >= d + 2]
    if not out:
        cannot.append({"effect": "track_straightness", "joints": [1],
                       "reason": f"the carriage stood at {distinct} positions only: a straightness error cannot be "
                                 "told from the track's direction"})
    return out

def _coupling(kin: Kinematics, q: np.ndarray, cannot: list) -> list[EffectChoice]:
    """Wrist coupling where the chain has a spherical wrist whose first two joints move (J4-J6 of a 6-axis arm:
    the options of the 6-axis candidate as they always were; J5-J7 of a 7-axis one)."""
    n = kin.n
    wrist = wrist_joints(kin)
    if not wrist:
        cannot.append({"effect": "axis_coupling", "joints": list(range(max(1, n - 2), n + 1)),
                       "reason": "no spherical wrist (the last three axes do not meet in a point): wrist coupling "
                                 "skipped"})
        return []
    a, b, _ = wrist
    if np.ptp(q[:, a - 1]) > 0 and np.ptp(q[:, b - 1]) > 0:
        return [EffectChoice("axis_coupling", () if n == 6 else (("joints", wrist),))]
    cannot.append({"effect": "axis_coupling", "joints": list(wrist),
                   "reason": f"needs a spherical wrist whose J{a} and J{b} move"})
    return []


def scan_orders(span_deg: float, n_values: int, opt: LibraryOptions = LibraryOptions()) -> tuple[int, ...]:
    """The orders (periods per revolution) a joint covering ``span_deg`` with ``n_values`` distinct angles is
    scanned over: above the low harmonics it is offered, with at least ``scan_min_periods`` periods over the span,
    up to ``scan_max_order`` and to ``scan_points_per_period`` values per period."""
    low = int(np.clip(span_deg // opt.degrees_per_harmonic, 1, len(opt.harmonics)))
    span = max(span_deg, 1e-9)
    first = max(opt.harmonics[low - 1] + 1, math.ceil(opt.scan_min_periods * 360.0 / span))
    last = min(opt.scan_max_order, math.floor(n_values * 360.0 / (opt.scan_points_per_period * span)))
    return tuple(range(first, last + 1))


def scan_families(q_rad: np.ndarray, opt: LibraryOptions = LibraryOptions()
                  ) -> tuple[list[tuple[EffectChoice, ...]], list[dict]]:
    """(families, cannot_tell): per joint that covers ``gear_min_span_deg``, the single-order cyclic errors
    ``gear_cyclic(Jj hk)`` of its ``scan_orders``; the selection takes at most one order of a family per round,
    chosen inside its cross-validation (``BlockedCV.scan_errors``)."""
    q = np.atleast_2d(q_rad)
    N, n = q.shape
    if N > opt.scan_max_rows:
        return [], [{"effect": "gear_cyclic", "joints": list(range(1, n + 1)),
                     "reason": f"cyclic errors of a higher order are scanned up to {opt.scan_max_rows} rows"}]
    out = []
    for j in range(1, n + 1):
        span = math.degrees(float(np.ptp(q[:, j - 1])))
        values = len(np.unique(np.round(np.degrees(q[:, j - 1]), 2)))
        orders = scan_orders(span, values, opt) if span >= opt.gear_min_span_deg else ()
        if orders:
            out.append(tuple(EffectChoice("gear_cyclic", (("joint", j), ("harmonics", (k,)))) for k in orders))
    return out, []


def _backlash(meta, N, n, opt, cannot) -> list[EffectChoice]:
    s = meta.get("approach")
    if s is None:
        cannot.append({"effect": "backlash", "joints": list(range(1, n + 1)),
                       "reason": "no measurement order: approach directions unknown"})
        return []
    s = np.asarray(s, float)
    need = max(opt.backlash_min_side, opt.backlash_min_side_fraction * N)
    joints = tuple(j for j in range(1, n + 1) if min(np.sum(s[:, j - 1] > 0), np.sum(s[:, j - 1] < 0)) >= need)
    if not joints:
        cannot.append({"effect": "backlash", "joints": list(range(1, n + 1)),
                       "reason": "approach directions never change (every joint is reached from the same side)"})
        return []
    return [EffectChoice("backlash", (("joints", joints),))]


def _lag(meta, n, opt, cannot) -> list[EffectChoice]:
    move = meta.get("move")
    if move is None:
        cannot.append({"effect": "readback_lag", "joints": list(range(1, n + 1)),
                       "reason": "no measurement order: the moves between points are unknown"})
        return []
    sd = np.degrees(np.std(np.asarray(move, float), axis=0))
    joints = tuple(j for j in range(1, n + 1) if sd[j - 1] >= opt.lag_min_move_std_deg)
    if not joints:
        cannot.append({"effect": "readback_lag", "joints": list(range(1, n + 1)),
                       "reason": "the joints hardly move between points"})
        return []
    return [EffectChoice("readback_lag", (("joints", joints), ("memory_joints", joints)))]


def _time(meta, N, opt, cannot, main=(1, 2, 3), p_base_mm=None) -> list[EffectChoice]:
    """Warm-up (timestamps or temperatures) and drift of the registration (in time, else in measurement order);
    neither when its clock follows the place (``_follows_place``; ``p_base_mm()``: the SMR positions (N, 3) mm)."""
    out = []
    t, temp, order = meta.get("t_s"), meta.get("temp_c"), meta.get("order")
    timed = t is not None and np.ptp(np.asarray(t, float)) >= opt.time_min_span_s
    warm = temp is not None and np.ptp(np.asarray(temp, float)) >= opt.temp_min_span_c

    def placed(effect: str, clock, name: str) -> bool:
        r2 = None if p_base_mm is None else _follows_place(np.asarray(clock, float), p_base_mm, opt)
        if r2 is not None:
            cannot.append({"effect": effect, "joints": [], "reason": f"the {name} follows the place in the workspace "
                           f"(a quadratic in the SMR position explains {r2:.0%} of it): a drift cannot be told from a "
                           "shape in space"})
        return r2 is not None

    if (timed or warm) and not placed("thermal_drift", temp if temp is not None else t,
                                      "temperature" if temp is not None else "time"):
        taus = opt.warmup_tau_s if (timed and not warm) else opt.warmup_tau_s[:1]
        out += [EffectChoice("thermal_drift", (("tau_s", tau), ("joints", main))) for tau in taus]
    elif not (timed or warm):
        cannot.append({"effect": "thermal_drift", "joints": list(main),
                       "reason": "no timestamps or temperatures in the data" if t is None and temp is None
                       else "the data span too short a time to reveal a warm-up"})
    if timed:
        clock, span = "t_s", float(np.max(np.asarray(t, float)))
    elif order is not None and N >= opt.min_order_points and np.ptp(np.asarray(order, float)) > 0:
        clock, span = "order", float(np.max(np.asarray(order, float)))
    else:
        cannot.append({"effect": "registration_drift", "joints": [],
                       "reason": "no timestamps and no measurement order" if order is None else
                       "too few points in measurement order"})
        return out
    if placed("registration_drift", t if timed else order, "time" if timed else "measurement order"):
        return out
    out += [EffectChoice("registration_drift", (("clock", clock), ("degree", d), ("span", max(span, 1e-9))))
            for d in (1, 2)]
    return out


def _follows_place(clock: np.ndarray, p_base_mm, opt: LibraryOptions) -> float | None:
    """The share of the clock's variance (N,) a quadratic in the SMR position explains, when it exceeds
    ``opt.clock_place_max_r2`` (the clock then stands for the place: a drift in it is a shape in space), else None."""
    if opt.clock_place_max_r2 is None or len(clock) < 20 or not np.ptp(clock) > 0:
        return None
    p = np.asarray(p_base_mm(), float)
    p = (p - p.mean(axis=0)) / np.maximum(p.std(axis=0), 1e-9)
    i, j = np.triu_indices(3)
    F = np.column_stack([np.ones(len(p)), p, p[:, i] * p[:, j]])          # 1, x, y, z and their 6 products
    u = clock - clock.mean()
    r2 = 1.0 - float(np.sum((u - F @ np.linalg.lstsq(F, u, rcond=None)[0]) ** 2)) / float(np.sum(u**2))
    return r2 if r2 > opt.clock_place_max_r2 else None


REFINED_FORMS = ("levers",)   # gravity compliance's free mass distributions offered once it is taken
LINKS_AFTER_LEVERS = True     # the links' complete gravity regressor offered once the lever form is taken (it must
#                               then gain over the lever form in the model; issue 32, fourteenth protocol,
#                               bench/bench_links_after_levers.py: kept, mean ratio 0.980, none worse)


def refinements(choice: EffectChoice, n_joints: int, refined_forms=None) -> list[EffectChoice]:
    """Candidates that refine an accepted effect: the free mass distribution of gravity compliance
    (``refined_forms``, by default ``REFINED_FORMS``: the lever points), then, once the lever form is taken
    (``LINKS_AFTER_LEVERS``), the links' complete gravity regressor, which also holds a centre of mass off a roll
    axis (offered beside the lever form instead, the ninth protocol of ``bench/bench_links_form.py`` did not keep
    it)."""
    opts = dict(choice.options)
    if choice.name != "joint_compliance":
        return []
    form = opts.get("form", "gravity")
    after_levers = ("links",) if form == "levers" and LINKS_AFTER_LEVERS else ()
    forms = (refined_forms or REFINED_FORMS) if form == "gravity" else after_levers
    return [EffectChoice("joint_compliance", (("joints", tuple(opts["joints"])), ("form", f),
                                              ("payload_cog_flange_mm", opts.get("payload_cog_flange_mm")),
                                              ("gravity_base", opts.get("gravity_base", (0.0, 0.0, -1.0)))))
            for f in forms]


def refinement_closure(candidates, n_joints: int) -> list[EffectChoice]:
    """Every refinement reachable from ``candidates`` (refinements of refinements too), not among them, level by
    level in the candidates' order."""
    out, level = [], list(candidates)
    while level:
        level = [r for c in level for r in refinements(c, n_joints) if r not in out and r not in candidates]
        level = list(dict.fromkeys(level))
        out += level
    return out


def parts(choice: EffectChoice) -> list[tuple[str, EffectChoice]]:
    """(label, the effect without that part) for every part the data may not need: one joint of backlash or a
    read-back lag, one harmonic, a lag's memory term, a thermal zero drift, the quadratic term of a drift. The
    joints of gravity compliance are not pruned: every loaded joint yields under its torque."""
    opts = dict(choice.options)
    out = []
    joints = tuple(opts.get("joints", ()))
    if choice.name == "backlash" and len(joints) > 1:   # compliance: every loaded joint yields (no joint pruned)
        out += [(f"J{j}", choice.with_options(joints=tuple(x for x in joints if x != j))) for j in joints]
    if choice.name == "gear_cyclic" and len(opts.get("harmonics", ())) > 1:
        hs = tuple(opts["harmonics"])
        out += [(f"h{h}", choice.with_options(harmonics=tuple(x for x in hs if x != h))) for h in hs]
    if choice.name == "readback_lag":
        mem = tuple(opts.get("memory_joints", ()))
        out += [(f"J{j} memory", choice.with_options(memory_joints=tuple(x for x in mem if x != j))) for j in mem]
        if len(joints) > 1:
            out += [(f"J{j}", choice.with_options(joints=tuple(x for x in joints if x != j),
                                                   memory_joints=tuple(x for x in mem if x != j)))
                    for j in joints if j not in mem]
    if choice.name == "thermal_drift" and joints:
        out += [(f"zero drift J{j}", choice.with_options(joints=tuple(x for x in joints if x != j))) for j in joints]
    if choice.name == "registration_drift" and opts.get("degree", 1) > 1:
        out.append(("quadratic term", choice.with_options(degree=opts["degree"] - 1)))
    return out
