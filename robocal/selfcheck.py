"""Withheld-effect self-check of the diagnosis: simulate campaigns where one (or two) effects are present but absent
from the starting model, diagnose them, and count what was found.

The self-check (``run_self_check``) draws its campaigns from ``robocal.truth``, a generator written from the
physics and independent of the candidates (lumped-mass gravity compliance whose J2 torque depends on q3, gear
harmonics including the 2nd, true backlash, a read-back lag proportional to the move, exponential warm-up,
tracker drift seen by reference nests, random measurement order; timestamps, nests and commanded joints present
or not at random). ``truth_input`` turns such a campaign into a ``DiagnosisInput`` the way ``campaign diagnose``
does with a CSV.

``simulate_campaign`` below is the older simulator built on ``robocal.effects`` (kept for the unit tests of the
candidate forms and the examples of docs/diagnosis.md).

The simulated campaign follows the protocol of effects.md §7.1/§8 on an IRB 2600-12/1.65 (DH table of
``configs/irb2600.yaml``): random geometric errors (seed 000 Table 2 magnitudes), the tracker 3-4 m away in a
random orientation, the SMR 50-80 mm off the J6 axis, 300 calibration + 100 test poses drawn over the joint
space with varied orientations, measured in random order over 2 h with timestamps, approach directions from row
order (so random), payload alternating 0 / 12 kg in 15-min blocks, and a repeatability burst at the end
(10 poses x 5 cycles in a fixed order, so every repeat of a pose is approached the same way) that gives the
noise floor. Noise: Leica AT960-class tracker model + ISO 9283 RP 0.04 mm.

The truths deliberately use *other functional forms* than the diagnosis candidates: compliance from lumped
link masses with random masses, off-line centres of mass and an offset payload (or the trigonometric ABB form),
warm-up curves exp / two time constants / hyperbolic / ramp with per-link growth, gear errors with random
harmonic sets up to the 3rd, backlash on random joints, coupling with random extra terms, and registration drift
linear or settling. Magnitudes are "typical" (effects.md §2.0) times U(0.5, 1.5).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .approach import approach_signs as approach_from_order
from .diagnose import DiagnosisInput, DiagnosisOptions, NestReadings, diagnose, moves_from_order
from .effects import (DEFAULT_LINK_MASSES_KG, EFFECT_NAMES, Effect, apply_effects, axis_coupling, backlash,
                      gear_cyclic, joint_compliance, lumped_compliance, registration_drift_curve, thermal_warmup)
from .frames import make_T, rotvec_to_matrix
from .kinematics import Kinematics, identification_jacobian, smr_base
from .noise import TrackerUncertainty, noise_floor_mm, repeatability_sigma_mm
from .repeats import noise_floor_from_repeats as repeat_floor, repeat_dof
from .simulate import SimulatedCell, random_geometric_errors
from .truth import LIBRARY_TRUTHS, CampaignShape, TruthCampaign, TruthProtocol, simulate

ARCSEC = np.pi / 180.0 / 3600.0
LABELS = ("none",) + EFFECT_NAMES


def irb2600() -> Kinematics:
    """Nominal IRB 2600-12/1.65 (configs/irb2600.yaml), Hayati beta on J2, SMR on the flange axis."""
    return Kinematics.from_table("dh", [-90, 0, -90, 90, 90, 0], [150, 700, 115, 0, 0, 0], [445, 0, 0, 795, 0, 85],
                                 [0, -90, 0, 0, 180, 0], [-180, -95, -180, -400, -120, -400],
                                 [180, 155, 75, 400, 120, 400], hayati_joints=[2], p_flange_smr_mm=[0, 0, 100])


@dataclass(frozen=True)
class Protocol(CampaignShape):
    """The simulated measurement protocol (see the module docstring)."""
    log_time: bool = True
    log_approach: bool = True


@dataclass(frozen=True)
class TruthEffect:
    name: str
    joints: tuple[int, ...]
    form: str
    magnitude: float
    visible_rms_mm: float = float("nan")     # RMS left after a noise-free geometric calibration


@dataclass(frozen=True, eq=False)
class SimulatedCampaign:
    """Rows in measurement order: ``sets`` calib / test / check; metadata logged as the protocol says."""
    nominal: Kinematics
    cell: SimulatedCell
    q_rad: np.ndarray
    p_mm: np.ndarray
    cov_mm2: np.ndarray
    sets: tuple[str, ...]
    point_id: tuple[str, ...]
    t_s: np.ndarray | None
    payload_kg: np.ndarray
    approach: np.ndarray
    truths: tuple[TruthEffect, ...]

    def mask(self, name: str) -> np.ndarray:
        return np.array([s == name for s in self.sets])

    def diagnosis_input(self) -> DiagnosisInput:
        """Calibration and test rows with the floor from the repeat burst (specs if it has too few repeats)."""
        check = self.mask("check")
        use = ~check
        floor = repeat_floor(np.degrees(self.q_rad[check]), self.p_mm[check]) if check.any() else None
        source = "repeats"
        if floor is None:
            floor = noise_floor_mm(self.p_mm[use], self.cell.tracker, self.cell.repeatability_rp_mm)
            source = "specs"
        dof = repeat_dof(np.degrees(self.q_rad[check])) if source == "repeats" else None
        return DiagnosisInput(self.nominal, self.q_rad[use], self.p_mm[use], self.cov_mm2[use],
                              self.mask("calib")[use], self.mask("test")[use], floor, source, dof,
                              t_s=None if self.t_s is None else self.t_s[use],
                              payload_kg=self.payload_kg[use],
                              approach=None if self.approach is None else self.approach[use])


# ============================================================================ poses and cell
def sample_poses(kin: Kinematics, rng: np.random.Generator, n: int) -> np.ndarray:
    """n joint vectors (rad) spread over the joint space with varied wrist orientations, SMR above the floor,
    away from the base column, |q5| >= 15 deg (no wrist singularity)."""
    lo = np.radians([-120, -50, -120, -180, -115, -180])
    hi = np.radians([120, 90, 60, 180, 115, 180])
    out = []
    while sum(len(o) for o in out) < n:
        q = rng.uniform(lo, hi, (4 * n, 6))
        p = smr_base(kin, q)
        ok = (p[:, 2] > 150) & (np.hypot(p[:, 0], p[:, 1]) > 450) & (np.abs(q[:, 4]) > np.radians(15))
        out.append(q[ok])
    return np.concatenate(out)[:n]


def _tracker_frame(rng) -> np.ndarray:
    """T_tracker_base: the robot 2.5-4 m from the tracker in a random direction, random yaw, slight tilt."""
    az = rng.uniform(-np.pi, np.pi)
    dist = rng.uniform(2500, 4000)
    t = np.array([dist * np.cos(az), dist * np.sin(az), rng.uniform(-1200, -600)])
    R = rotvec_to_matrix(np.array([0, 0, rng.uniform(-np.pi, np.pi)]) + rng.normal(0, 0.01, 3))
    return make_T(R, t)


def _smr(rng) -> np.ndarray:
    phi = rng.uniform(-np.pi, np.pi)
    r = rng.uniform(50, 80)
    return np.array([r * np.cos(phi), r * np.sin(phi), rng.uniform(80, 120)])


# ============================================================================ truths with other forms
def truth_effect(name: str, rng: np.random.Generator, magnitude: float) -> tuple[TruthEffect, Effect, np.ndarray]:
    """A random instance of a library effect at ``magnitude`` x typical, in a functional form that differs from
    the diagnosis candidate."""
    m = magnitude
    u = lambda a, b, size=None: rng.uniform(a, b, size)                        # noqa: E731
    sign = lambda: rng.choice([-1.0, 1.0])                                     # noqa: E731
    if name == "joint_compliance":
        if rng.random() < 0.7:
            masses = np.array(DEFAULT_LINK_MASSES_KG) * u(0.7, 1.3, 6)
            eff = lumped_compliance((2, 3), masses, u(0.3, 0.7, 6), u(-60, 60, 6),
                                    (u(-30, 30), u(-30, 30), u(50, 150)))
            params = np.array([3.3e-7, 6.7e-7]) * m * u(0.7, 1.4, 2)
            return TruthEffect(name, (2, 3), "lumped masses, off-line COMs, offset payload", m), eff, params
        eff = joint_compliance(form="trig")
        params = np.array(eff.typical) * m * u(0.7, 1.4, 5) * np.array([1, sign(), sign(), sign(), sign()])
        return TruthEffect(name, (2, 3), "trigonometric (ABB) form, no payload term", m), eff, params
    if name == "payload_deflection":
        eff = lumped_compliance((2, 3), np.zeros(6), 0.5, 0.0, (u(-40, 40), u(-40, 40), u(50, 200)),
                                name="payload_deflection")
        params = np.array([3.3e-7, 6.7e-7]) * m * u(0.7, 1.4, 2)
        return TruthEffect(name, (2, 3), "payload torque, offset payload COM", m), eff, params
    if name == "gear_cyclic":
        joint = int(rng.integers(1, 7))
        sets = [(1, 2), (1,), (2,), (1, 3), (2, 3), (1, 2, 3)]
        harmonics = sets[int(rng.integers(len(sets)))]
        base = 15.0 if joint <= 3 else 45.0                                   # arcsec, h = 1
        amp = [(base if h == 1 else base / 2) * ARCSEC * m * u(0.67, 1.33) for h in harmonics]
        phase = u(-np.pi, np.pi, len(harmonics))
        params = np.ravel([[a * np.cos(f), a * np.sin(f)] for a, f in zip(amp, phase)])
        return (TruthEffect(name, (joint,), f"harmonics {','.join(map(str, harmonics))}", m),
                gear_cyclic(joint, harmonics), params)
    if name == "backlash":
        joints = sorted(rng.choice([1, 2, 3], size=int(rng.integers(1, 4)), replace=False).tolist())
        if rng.random() < 0.3:
            joints.append(int(rng.choice([4, 5])))
        eff = backlash(tuple(joints))
        params = np.array([u(0.5, 1.0) / 60 * np.pi / 180 * m for _ in joints])
        return TruthEffect(name, tuple(joints), "dead band", m), eff, params
    if name == "thermal_drift":
        curve = ["exp", "two_exp", "hyperbolic", "ramp"][int(rng.integers(4))]
        tau = {"exp": u(1800, 5400), "two_exp": 1080.0, "hyperbolic": u(1080, 3600), "ramp": u(2700, 5400)}[curve]
        growth = 1.2e-4 * m * u(0.5, 1.5, 6) * np.where(rng.random(6) < 0.3, 2.0, 1.0)
        zero = np.zeros(6)
        zero[1:3] = 8.7e-5 * m * u(0.5, 1.5, 2) * np.array([sign(), sign()])
        if rng.random() < 0.3:
            zero[0] = 8.7e-5 * m * u(0.5, 1.5) * sign()
        eff = thermal_warmup(growth, zero, curve, tau, tau2_s=5400.0, mix=u(0.3, 0.7))
        return TruthEffect(name, tuple(int(j) + 1 for j in np.flatnonzero(zero)), f"{curve} tau {tau / 60:.0f} min",
                           m), eff, np.array([1.0])
    if name == "axis_coupling":
        eff = axis_coupling()
        params = np.array([4e-3 * sign(), u(-2e-3, 2e-3) * (rng.random() < 0.5),
                           u(-2e-3, 2e-3) * (rng.random() < 0.5)]) * m * u(0.8, 1.25)
        joints = sorted({5, 6} | ({4} if np.any(params[1:] != 0) else set()))
        return TruthEffect(name, tuple(joints), "wrist coupling", m), eff, params
    if name == "registration_drift":
        curve = "linear" if rng.random() < 0.5 else "exp"
        d = rng.normal(size=3)
        w = rng.normal(size=3)
        scale = 1.0 if curve == "linear" else 2.0                             # per hour vs. final offset over 2 h
        v = 0.03 * scale * m * u(0.7, 1.3) * d / np.linalg.norm(d)
        w = 10e-6 * scale * m * u(0.7, 1.3) * w / np.linalg.norm(w)
        tau = u(1200, 3600)
        eff = registration_drift_curve(v, w, curve, tau)
        return TruthEffect(name, (), curve if curve == "linear" else f"settling tau {tau / 60:.0f} min", m), eff, \
            np.array([1.0])
    raise ValueError(f"unknown effect {name!r}")


# ============================================================================ the simulated campaign
def simulate_campaign(effects: Sequence[str], seed: int, magnitude: float | None = None,
                      protocol: Protocol = Protocol()) -> SimulatedCampaign:
    """One campaign with the named effects present (magnitude None: U(0.5, 1.5) per effect)."""
    rng = np.random.default_rng(seed)
    nominal = irb2600()
    smr = _smr(rng)
    truth_geo = random_geometric_errors(nominal, rng).with_(T_tracker_base=_tracker_frame(rng), p_flange_smr_mm=smr)
    nominal = nominal.with_(p_flange_smr_mm=smr + rng.normal(0, 0.5, 3))
    pr = protocol
    n_main = pr.n_calib + pr.n_test
    q_main = sample_poses(nominal, rng, n_main)
    sets = np.array(["calib"] * pr.n_calib + ["test"] * pr.n_test)[rng.permutation(n_main)]
    dt = pr.duration_s / n_main
    t_main = (np.arange(n_main) + rng.uniform(0, 0.5, n_main)) * dt
    q_chk = sample_poses(nominal, rng, pr.check_poses)
    order = [pr.check_poses - 1] + list(range(pr.check_poses)) * pr.check_repeats
    q = np.concatenate([q_main, q_chk[order]])
    set_names = list(sets) + ["calib"] + ["check"] * (len(order) - 1)
    ids = [f"P{i:04d}" for i in range(n_main)] + ["P-lead"] + [f"CHK{k:02d}" for k in order[1:]]
    t = np.concatenate([t_main, pr.duration_s + 6.0 * np.arange(1, len(order) + 1)])
    block = (t // pr.payload_block_s).astype(int) % len(pr.payloads_kg)
    payload = np.asarray(pr.payloads_kg, float)[block]
    payload[n_main:] = pr.payloads_kg[0]
    approach = approach_from_order(q)
    meta = {"t_s": t, "payload_kg": payload, "approach": approach}
    truths, pairs = [], []
    for name in effects:
        mag = float(rng.uniform(0.5, 1.5)) if magnitude is None else float(magnitude)
        te, eff, params = truth_effect(name, rng, mag)
        truths.append(te)
        pairs.append((eff, params))
    cell = SimulatedCell(truth_geo, tuple(pairs), TrackerUncertainty(), pr.repeatability_rp_mm)
    p, cov = cell.measure(q, rng, meta)
    cov = cov + repeatability_sigma_mm(pr.repeatability_rp_mm) ** 2 * np.eye(3)
    calib = np.array([s == "calib" for s in set_names])
    truths = [_with_visible(te, cell, eff, params, q[calib], {k: v[calib] for k, v in meta.items()})
              for te, (eff, params) in zip(truths, pairs)]
    return SimulatedCampaign(nominal, cell, q, p, cov, tuple(set_names), tuple(ids),
                             t if pr.log_time else None, payload, approach if pr.log_approach else None, tuple(truths))


def _with_visible(te: TruthEffect, cell: SimulatedCell, eff, params, q, meta) -> TruthEffect:
    """RMS of the effect's displacement left after a (noise-free, linearised) geometric calibration."""
    e = apply_effects(cell.truth, q, meta, [(eff, params)]) - apply_effects(cell.truth, q, meta, [])
    _, J = identification_jacobian(cell.truth, q)
    A = J.reshape(-1, J.shape[2])
    nrm = np.linalg.norm(A, axis=0)
    A = A[:, nrm > 0] / nrm[nrm > 0]
    beta = np.linalg.lstsq(A, e.reshape(-1), rcond=1e-8)[0]
    vis = e.reshape(-1) - A @ beta
    return TruthEffect(te.name, te.joints, te.form, te.magnitude, float(np.sqrt(np.mean(np.sum(vis.reshape(-1, 3) ** 2,
                                                                                              axis=1)))))


# ============================================================================ truth campaigns -> diagnosis input
def truth_input(camp: TruthCampaign, with_qc: bool = False, with_nests: bool = True,
                baseline=None) -> DiagnosisInput:
    """Calibration and test rows of a truth campaign as ``campaign diagnose`` sees a CSV: read-back joints as q,
    moves and approach directions from the full row order, the floor from the repeat burst (grouped by the
    commanded joints), commanded joints and reference nests when asked for."""
    check = camp.mask("check")
    use = ~check
    q_full = camp.q_read_rad
    move, prev = moves_from_order(q_full)
    approach = approach_from_order(q_full)
    floor = repeat_floor(np.degrees(camp.q_cmd_rad[check]), camp.p_mm[check]) if check.any() else None
    source, dof = "repeats", None
    if floor is None:
        floor = noise_floor_mm(camp.p_mm[use], TrackerUncertainty(), camp.protocol.repeatability_rp_mm)
        source = "specs"
    else:
        dof = repeat_dof(np.degrees(camp.q_cmd_rad[check]))
    nests = None
    if with_nests and len(camp.nest_p_mm):
        nests = NestReadings(camp.nest_p_mm, camp.nest_id, camp.nest_t_s, camp.nest_after_row + 0.5)
    return DiagnosisInput(camp.nominal, q_full[use], camp.p_mm[use], camp.cov_mm2[use], camp.mask("calib")[use],
                          camp.mask("test")[use], floor, source, dof,
                          t_s=None if camp.t_s is None else camp.t_s[use], payload_kg=camp.payload_kg[use],
                          approach=approach[use], move_rad=move[use], prev_move_rad=prev[use],
                          qc_rad=camp.q_cmd_rad[use] if with_qc else None, nests=nests,
                          order=np.flatnonzero(use).astype(float))


# ============================================================================ trials and summary
@dataclass(frozen=True)
class Trial:
    kind: str                        # single | control | combo | outside
    seed: int
    truths: tuple                    # truth.TruthEffect
    diagnosed: tuple[str, ...]       # accepted effects in selection order
    diagnosed_joints: tuple[tuple[int, ...], ...]
    classes: tuple[tuple[str, ...], ...]   # per accepted effect: itself + its confusable class
    baseline_test_rms_mm: float
    final_test_rms_mm: float
    noise_floor_mm: float
    unexplained: bool
    shrinkage: tuple[tuple[str, float, float], ...]   # (effect, predicted, achieved) per accepted effect
    seconds: float
    setting: str = ""                # timestamps / nests / commanded joints present

    @property
    def truth_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.truths if t.name in EFFECT_NAMES)

    @property
    def acceptable(self) -> set[str]:
        """Names that are not spurious: the truths, and for a reach-dependent sag (outside the library) the
        gravity-elastic class it belongs to (compliance, link bending and base compliance look alike)."""
        ok = set(self.truth_names)
        if any(t.name == "reach_deflection" for t in self.truths):
            ok |= {"joint_compliance", "payload_deflection"}
        return ok

    @property
    def primary(self) -> str:
        return self.diagnosed[0] if self.diagnosed else "none"

    @property
    def named_right(self) -> bool:
        """The first accepted effect is the truth or names it in its confusable class (single-effect trials)."""
        return bool(self.truth_names) and bool(self.classes) and self.truth_names[0] in self.classes[0]

    @property
    def spurious(self) -> int:
        """Accepted effects whose class contains no true effect."""
        truth = self.acceptable
        return sum(1 for c in self.classes if not truth & set(c))

    @property
    def exact(self) -> bool:
        return set(self.diagnosed) == set(self.truth_names) and len(self.diagnosed) == len(set(self.diagnosed))

    @property
    def joints_ok(self) -> bool:
        """Every true effect found; gear, backlash and lag on exactly the true joints."""
        got = dict(zip(self.diagnosed, self.diagnosed_joints))
        for t in self.truths:
            if t.name not in EFFECT_NAMES:
                continue
            if t.name not in got:
                return False
            if t.name in ("gear_cyclic", "backlash", "readback_lag") and set(got[t.name]) != set(t.joints):
                return False
        return True

    def to_dict(self) -> dict:
        return {"kind": self.kind, "seed": self.seed, "setting": self.setting,
                "truth": [{"effect": t.name, "joints": list(t.joints), "form": t.form} for t in self.truths],
                "diagnosed": list(self.diagnosed), "diagnosed_joints": [list(j) for j in self.diagnosed_joints],
                "classes": [list(c) for c in self.classes], "named_right": self.named_right,
                "spurious": self.spurious, "exact": self.exact,
                "joints_ok": self.joints_ok if self.truths else None,
                "baseline_test_rms_mm": self.baseline_test_rms_mm, "final_test_rms_mm": self.final_test_rms_mm,
                "noise_floor_mm": self.noise_floor_mm, "unexplained": self.unexplained,
                "shrinkage": [{"effect": e, "predicted_mm": p, "achieved_mm": a} for e, p, a in self.shrinkage],
                "seconds": self.seconds}


def trial_setting(effects: Sequence[str], seed: int) -> tuple[TruthProtocol, bool]:
    """Random metadata of a trial (seeded): timestamps withheld in a quarter of the campaigns without time
    effects, reference nests in half, commanded joints in a third."""
    rng = np.random.default_rng(seed + 77_000)
    timed = any(e in ("thermal_drift", "registration_drift") for e in effects)
    stamps = timed or rng.random() >= 0.25
    nests = rng.random() < 0.5 or ("registration_drift" in effects and not stamps)
    return TruthProtocol(timestamps=stamps, nest_every=20 if nests else 0), bool(rng.random() < 1 / 3)


def run_trial(kind: str, effects: Sequence[str], seed: int, options: DiagnosisOptions = DiagnosisOptions(),
              protocol: TruthProtocol | None = None, with_qc: bool | None = None) -> Trial:
    pr, qc = trial_setting(effects, seed)
    pr = pr if protocol is None else protocol
    qc = qc if with_qc is None else with_qc
    camp = simulate(effects, seed, pr)
    t0 = time.perf_counter()
    d = diagnose(truth_input(camp, with_qc=qc), options)
    secs = time.perf_counter() - t0
    acc = [f for f in d.findings if f.accepted]
    shrink = tuple((f.effect, float(f.evidence["predicted_shrinkage_mm"]), float(f.evidence["achieved_shrinkage_mm"]))
                   for f in acc)
    classes = tuple(tuple([f.effect] + [c["effect"] for c in f.evidence.get("confusable_with", [])]) for f in acc)
    setting = ", ".join(x for x, on in (("timestamps", pr.timestamps), ("nests", pr.nest_every > 0),
                                         ("commanded joints", qc)) if on) or "no timestamps, nests or qc"
    return Trial(kind, seed, camp.truths, tuple(f.effect for f in acc), tuple(tuple(f.joints) for f in acc), classes,
                 d.baseline_test_rms_mm, d.final_test_rms_mm, d.noise_floor_mm, d.unexplained, shrink, secs, setting)


def trial_plan(seeds: int = 5, controls: int | None = None, combos: int | None = None,
               effects: Sequence[str] = LIBRARY_TRUTHS, first_seed: int = 1000, outside: int | None = None
               ) -> list[tuple[str, tuple, int]]:
    """(kind, effects, seed) of a self-check: ``seeds`` per effect, controls (default 2 x seeds), two-effect
    combinations (default 2 x seeds, random pairs that are not both elastic) and campaigns with an effect outside
    the library (reach-dependent sag, default seeds)."""
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
    return plan


@dataclass(frozen=True)
class SelfCheckResult:
    trials: tuple[Trial, ...]
    seconds: float

    def confusion(self) -> dict[str, dict[str, int]]:
        """Single-effect trials and controls: truth -> primary (first accepted) diagnosis -> count."""
        m = {a: {b: 0 for b in LABELS} for a in LABELS}
        for t in self.trials:
            if t.kind in ("single", "control"):
                truth = t.truth_names[0] if t.truth_names else "none"
                m[truth][t.primary] += 1
        return m

    def summary(self) -> dict:
        singles = [t for t in self.trials if t.kind == "single"]
        controls = [t for t in self.trials if t.kind == "control"]
        combos = [t for t in self.trials if t.kind == "combo"]
        outside = [t for t in self.trials if t.kind == "outside"]
        per_effect = {}
        for name in EFFECT_NAMES:
            ts = [t for t in singles if t.truth_names == (name,)]
            if ts:
                per_effect[name] = {"n": len(ts), "named_right": sum(t.named_right for t in ts),
                                    "primary_correct": sum(t.primary == name for t in ts),
                                    "exact": sum(t.exact for t in ts), "joints_ok": sum(t.joints_ok for t in ts)}
        tp = sum(len(set(t.diagnosed) & set(t.truth_names)) for t in combos)
        n_true = sum(len(t.truth_names) for t in combos)
        n_diag = sum(len(t.diagnosed) for t in combos)
        errs = [(p - a) for t in self.trials for e, p, a in t.shrinkage if e in t.truth_names]
        achieved = [a for t in self.trials for e, p, a in t.shrinkage if e in t.truth_names]
        n_all = len(self.trials)
        spurious = sum(t.spurious for t in self.trials)
        return {
            "single_trials": len(singles),
            "named_right": sum(t.named_right for t in singles),
            "primary_correct": sum(t.primary == t.truth_names[0] for t in singles),
            "exact_set": sum(t.exact for t in singles),
            "joints_ok": sum(t.joints_ok for t in singles),
            "per_effect": per_effect,
            "controls": len(controls), "controls_clean": sum(not t.diagnosed for t in controls),
            "controls_unexplained": sum(t.unexplained for t in controls),
            "combo_trials": len(combos), "combo_exact": sum(t.exact for t in combos),
            "combo_recall": tp / n_true if n_true else None, "combo_precision": tp / n_diag if n_diag else None,
            "outside_trials": len(outside), "outside_unexplained": sum(t.unexplained for t in outside),
            "outside_spurious": sum(t.spurious for t in outside),
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
        """Done-when of the diagnosis: >= 95 % of single effects named right, >= 95 % of controls clean,
        <= 1 spurious acceptance per 20 datasets."""
        s = self.summary()
        return (s["single_trials"] > 0 and s["named_right"] >= 0.95 * s["single_trials"]
                and s["controls_clean"] >= 0.95 * s["controls"] and s["spurious_per_20"] <= 1.0)

    def to_dict(self) -> dict:
        return {"summary": self.summary(), "confusion": self.confusion(), "labels": list(LABELS),
                "trials": [t.to_dict() for t in self.trials], "passed": self.passed()}


def run_self_check(seeds: int = 5, controls: int | None = None, combos: int | None = None,
                   options: DiagnosisOptions = DiagnosisOptions(), outside: int | None = None,
                   progress: Callable[[int, int, Trial], None] | None = None) -> SelfCheckResult:
    """Run the whole withheld-effect self-check (see ``trial_plan``) on truth campaigns."""
    plan = trial_plan(seeds, controls, combos, outside=outside)
    t0 = time.perf_counter()
    trials = []
    for i, (kind, effects, seed) in enumerate(plan):
        trial = run_trial(kind, effects, seed, options)
        trials.append(trial)
        if progress:
            progress(i + 1, len(plan), trial)
    return SelfCheckResult(tuple(trials), time.perf_counter() - t0)


SHORT = {"none": "none", "joint_compliance": "comp", "payload_deflection": "pay", "gear_cyclic": "cyc",
         "backlash": "back", "readback_lag": "lag", "thermal_drift": "therm", "axis_coupling": "coup",
         "registration_drift": "tdrift"}


def format_confusion(result: SelfCheckResult) -> str:
    """Plain-text confusion matrix (truth rows x primary diagnosis columns) with short labels."""
    m = result.confusion()
    lines = ["truth \\ diagnosed | " + " | ".join(SHORT[b] for b in LABELS)]
    for a in LABELS:
        if sum(m[a].values()):
            lines.append(f"{SHORT[a]} | " + " | ".join(str(m[a][b]) if m[a][b] else "." for b in LABELS))
    return "\n".join(lines)
