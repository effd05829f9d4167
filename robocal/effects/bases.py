"""Non-geometric effect models (the catalogue of docs/diagnosis.md §1), each linear in its parameters.

An effect maps joint angles ``q_rad (N, n)`` and per-point metadata to a *basis* with K columns:

* ``dq``    (N, n, K): joint-angle deviation per unit parameter (rad),
* ``scale`` (N, K):    relative growth of every link length a_i, d_i per unit parameter,
* ``dp``    (N, 3, K): SMR displacement in the tracker frame per unit parameter (mm).

The same basis both *simulates* a robot (``apply_effects``: exact FK with ``q + dq`` and scaled links)
and *extends* a model as extra parameters (``effect_regressor``: the linearised tracker-frame columns).
Metadata keys (all optional, arrays of N): ``t_s`` time since the campaign start (s), ``temp_c``,
``payload_kg``, ``approach`` (N, n) sign of the last motion of each joint (+1/-1/0), ``move`` / ``prev_move``
(N, n) rad the signed last move and the one before, ``order`` position in the measurement sequence. A missing
key makes the effect's contribution zero (a commanded target has no read-back lag, no drift clock).
Joint numbers in names and ``joints`` are 1-based. Gravity acts through the one torque model ``gravity_torques``
(lumped link masses of ``GravityModel``, payload at its centre of gravity, gravity direction in the base frame).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from robocal.kinematics.frames import skew, transform_points
from robocal.kinematics.gravity import (default_link_masses, gravity_torques, lever_torques, link_mass_torques,
                                       link_masses)
from robocal.kinematics.models import Kinematics, ParamLayout, chain, identification_jacobian, joint_motion_columns
EFFECT_NAMES = ("joint_compliance", "payload_deflection", "gear_cyclic", "backlash", "readback_lag", "thermal_drift",
                "axis_coupling", "registration_drift")     # every effect of the library, in report order
TRACK_EFFECTS = ("track_straightness",)   # effects of a linear track (chains with one)
# what the mock robot can simulate (a read-back lag is an artefact of the controller's report, simulated apart)
SIMULATED_EFFECTS = tuple(name for name in EFFECT_NAMES if name != "readback_lag") + TRACK_EFFECTS
MODEL_EFFECTS = EFFECT_NAMES + TRACK_EFFECTS   # every library effect can be a parameter of the calibrated model


@dataclass(frozen=True)
class Basis:
    dq: np.ndarray | None = None
    scale: np.ndarray | None = None
    dp: np.ndarray | None = None


@dataclass(frozen=True)
class Effect:
    """A candidate effect: name, 1-based joints, parameter names and units, basis function, typical values."""
    name: str
    joints: tuple[int, ...]
    param_names: tuple[str, ...]
    unit: str
    basis_fn: Callable[[Kinematics, np.ndarray, Mapping], Basis] = field(repr=False, compare=False)
    typical: tuple[float, ...] = ()
    needs: tuple[str, ...] = ()       # metadata keys required to observe it

    @property
    def k(self) -> int:
        return len(self.param_names)

    def basis(self, kin: Kinematics, q_rad: np.ndarray, meta: Mapping) -> Basis:
        return self.basis_fn(kin, np.atleast_2d(q_rad), meta)

    def observable(self, meta: Mapping) -> bool:
        return all(meta.get(k) is not None for k in self.needs)


def _zeros_dq(q, k):
    return np.zeros(q.shape + (k,))


def _meta(meta, key, n, default=0.0):
    v = meta.get(key)
    return np.full(n, default, float) if v is None else np.asarray(v, float)


# ---------------------------------------------------------------- effect factories (gravity: robocal.kinematics.gravity)
def joint_compliance(joints=(2, 3), form: str = "gravity", link_masses_kg=None,
                     payload_cog_flange_mm=None, gravity_base=(0.0, 0.0, -1.0), n_joints: int = 6) -> Effect:
    """Joint compliance under gravity.

    ``gravity``: dq_j = c_j * tau_j(q, payload), c_j compliance in rad/(N·m), tau the ``gravity_torques`` of the
    lumped link masses + payload (its centre of gravity ``payload_cog_flange_mm`` in the flange frame).
    ``levers``: the mass distribution left free: dq_j = sum_p c_jp * tau_jp(q) over the ``lever_torques`` points
    of joint j (torque per kg) + the payload torque, c_jp in rad·kg/(N·m) (compliance x mass).
    ``links``: the same with the complete gravity regressor of the links (``link_mass_torques``: per link a kg at
    its frame's origin and displaced along its three axes), which also holds a centre of mass off a roll axis.
    ``trig`` (seed 001 eq. 21-22, controller angles): dq2 = k1 s2 + k2 s23 + k3 c23; dq3 = k4 s23 + k5 c23 (rad).
    """
    if form == "trig":
        def basis(kin, q, meta):
            dq = _zeros_dq(q, 5)
            s2, s23, c23 = np.sin(q[:, 1]), np.sin(q[:, 1] + q[:, 2]), np.cos(q[:, 1] + q[:, 2])
            dq[:, 1, 0], dq[:, 1, 1], dq[:, 1, 2] = s2, s23, c23
            dq[:, 2, 3], dq[:, 2, 4] = s23, c23
            return Basis(dq=dq)
        return Effect("joint_compliance", (2, 3), ("k1", "k2", "k3", "k4", "k5"), "rad", basis,
                      typical=(2e-4, 1e-4, 1e-4, 1e-4, 1e-4))
    if form in ("levers", "links"):
        return _mass_compliance(tuple(joints), payload_cog_flange_mm, gravity_base, n_joints, form)
    if form != "gravity":
        raise ValueError(f"unknown compliance form {form!r} (expected gravity, levers, links or trig)")

    def basis(kin, q, meta):
        masses = default_link_masses(kin.n) if link_masses_kg is None else link_masses_kg
        tau = gravity_torques(kin, q, link_masses(kin.n, masses), _meta(meta, "payload_kg", len(q)),
                              payload_cog_flange_mm, gravity_base)
        dq = _zeros_dq(q, len(joints))
        for k, j in enumerate(joints):
            dq[:, j - 1, k] = tau[:, j - 1]
        return Basis(dq=dq)
    return Effect("joint_compliance", tuple(joints), tuple(f"c{j}" for j in joints), "rad/(N*m)", basis,
                  typical=tuple(compliance_typical(j) for j in joints))


def compliance_typical(joint: int) -> float:
    """Typical compliance (rad/(N·m)) of a 1-based joint of an industrial arm under gravity."""
    return {1: 2e-7, 2: 3.3e-7, 3: 6.7e-7}.get(joint, 3e-6)


def _mass_compliance(joints, payload_cog_flange_mm, gravity_base, n, form: str) -> Effect:
    """The free mass distribution: per joint, its columns of torque per kg (``lever_torques`` for ``levers``,
    ``link_mass_torques`` for ``links``) and the payload's torque (N·m)."""
    torques = lever_torques if form == "levers" else link_mass_torques

    def basis(kin, q, meta):
        pay = _meta(meta, "payload_kg", len(q))
        tau_pay = gravity_torques(kin, q, np.zeros(kin.n), pay, payload_cog_flange_mm, gravity_base)
        per_kg = torques(kin, q, joints, gravity_base)
        cols = [(j, np.concatenate([per_kg[j][0], tau_pay[:, j - 1:j]], axis=1)) for j in joints]
        dq = _zeros_dq(q, sum(c.shape[1] for _, c in cols))
        at = 0
        for j, c in cols:
            dq[:, j - 1, at:at + c.shape[1]] = c
            at += c.shape[1]
        return Basis(dq=dq)
    points = _mass_points(joints, n, form)
    names = tuple(f"c{j}_{p}" for j in joints for p in points[j] + ("payload",))
    return Effect("joint_compliance", joints, names, "rad*kg/(N*m)", basis, typical=_mass_typical(joints, n, points))


def _mass_points(joints, n: int, form: str) -> dict[int, tuple[str, ...]]:
    """{joint: the names of its mass columns} of the lever or the link form (the torque functions' names)."""
    if form == "levers":
        return {j: tuple(f"o{i + 1}" for i in range(j, n)) + ("flange", "beside") for j in joints}
    return {j: tuple(f"L{i + 1}{s}" for i in range(j - 1, n) for s in "oxyz")[2:] for j in joints}


def _mass_typical(joints, n: int, points) -> tuple[float, ...]:
    """Typical values of a free mass distribution's parameters (rad·kg/(N·m)): per joint, its typical compliance
    times, for the lever form, the default moving mass downstream of it shared over its points; for the link form,
    each link's default mass on its origin and each offset column (a link's mass 100 mm off its frame's origin). The
    payload column takes the compliance itself (its regressor is the payload's torque, N·m). At these values the
    form deflects the joints by the order of the gravity form at its typical values."""
    masses = default_link_masses(n)
    out = []
    for j in joints:
        c, names = compliance_typical(j), points[j]
        if names[-1] == "beside":
            out += [c * sum(masses[j - 1:]) / len(names)] * len(names) + [c]
        else:
            out += [c * masses[int(p[1:-1]) - 1] for p in names] + [c]
    return tuple(out)


def payload_deflection(joints=(2, 3), payload_cog_flange_mm=None, gravity_base=(0.0, 0.0, -1.0)) -> Effect:
    """Deflection from the payload's gravity torque only (a balanced arm): dq_j = c_j * tau_payload_j
    (rad/(N·m))."""
    def basis(kin, q, meta):
        tau = gravity_torques(kin, q, np.zeros(kin.n), _meta(meta, "payload_kg", len(q)), payload_cog_flange_mm,
                              gravity_base)
        dq = _zeros_dq(q, len(joints))
        for k, j in enumerate(joints):
            dq[:, j - 1, k] = tau[:, j - 1]
        return Basis(dq=dq)
    return Effect("payload_deflection", tuple(joints), tuple(f"c{j}" for j in joints), "rad/(N*m)", basis,
                  typical=tuple(5e-7 for _ in joints), needs=("payload_kg",))


def gear_cyclic(joint: int, harmonics=(1, 2)) -> Effect:
    """Cyclic transmission error of one joint: dq = sum_h a_h sin(h q) + b_h cos(h q) (rad)."""
    def basis(kin, q, meta):
        dq = _zeros_dq(q, 2 * len(harmonics))
        for k, h in enumerate(harmonics):
            dq[:, joint - 1, 2 * k] = np.sin(h * q[:, joint - 1])
            dq[:, joint - 1, 2 * k + 1] = np.cos(h * q[:, joint - 1])
        return Basis(dq=dq)
    names = tuple(f"{ab}{h}" for h in harmonics for ab in ("sin", "cos"))
    typical = tuple(7e-5 if h == 1 else 3.5e-5 for h in harmonics for _ in (0, 1))
    return Effect("gear_cyclic", (joint,), names, "rad", basis, typical=typical)


def backlash(joints=(1, 2, 3)) -> Effect:
    """Lost motion: dq_j = (b_j / 2) * s_j, s_j the sign of the last motion of joint j (rad)."""
    def basis(kin, q, meta):
        s = meta.get("approach")
        s = np.zeros_like(q) if s is None else np.asarray(s, float)
        dq = _zeros_dq(q, len(joints))
        for k, j in enumerate(joints):
            dq[:, j - 1, k] = 0.5 * s[:, j - 1]
        return Basis(dq=dq)
    return Effect("backlash", tuple(joints), tuple(f"b{j}" for j in joints), "rad", basis,
                  typical=tuple(2.9e-4 for _ in joints), needs=("approach",))


def readback_lag(joints=(1, 2, 3), memory_joints=()) -> Effect:
    """Read-back lag: the reported joint is off by lambda_j x (signed last move) [+ mu_j x (the move before)], so
    the robot really stood at dq_j = p_j * move_j + m_j * prev_move_j from the reported angle (p_j = -lambda_j,
    rad per rad of move). ``move``/``prev_move`` (N, n) rad come from the rows in measurement order; without them
    (a commanded target) the effect is zero: a lag is in the report of a position, not in the robot."""
    def basis(kin, q, meta):
        move, prev = meta.get("move"), meta.get("prev_move")
        dq = _zeros_dq(q, len(joints) + len(memory_joints))
        for k, j in enumerate(joints):
            if move is not None:
                dq[:, j - 1, k] = np.asarray(move, float)[:, j - 1]
        for k, j in enumerate(memory_joints):
            if prev is not None:
                dq[:, j - 1, len(joints) + k] = np.asarray(prev, float)[:, j - 1]
        return Basis(dq=dq)
    names = tuple(f"lag{j}" for j in joints) + tuple(f"lag{j}_memory" for j in memory_joints)
    return Effect("readback_lag", tuple(sorted(set(joints) | set(memory_joints))), names, "rad/rad", basis,
                  typical=tuple(-5e-4 for _ in names), needs=("move",))


def warmup(meta, n, tau_s):
    """Thermal state u in [0, 1): from temperature rise when logged (per K: from the first row's temperature, or
    ``temp_ref_c`` in a block of rows, ``meta_rows``), else 1 - exp(-t/tau)."""
    temp = meta.get("temp_c")
    if temp is not None:
        temp = np.asarray(temp, float)
        return temp - meta.get("temp_ref_c", temp[0])
    return 1.0 - np.exp(-_meta(meta, "t_s", n) / tau_s)


def thermal_drift(tau_s: float = 2700.0, joints=(2, 3)) -> Effect:
    """Warm-up: all link lengths grow by g_L*u and joint zeros drift by g_j*u, u = 1 - exp(-t/tau)."""
    def basis(kin, q, meta):
        u = warmup(meta, len(q), tau_s)
        dq = _zeros_dq(q, 1 + len(joints))
        scale = np.zeros((len(q), 1 + len(joints)))
        scale[:, 0] = u
        for k, j in enumerate(joints):
            dq[:, j - 1, k + 1] = u
        return Basis(dq=dq, scale=scale)
    return Effect("thermal_drift", tuple(joints), ("g_length",) + tuple(f"g_zero{j}" for j in joints), "1 or rad",
                  basis, typical=(1.2e-4,) + tuple(8.7e-5 for _ in joints), needs=("t_s",))


def axis_coupling(joints=(4, 5, 6)) -> Effect:
    """Wrist coupling / ratio error of the wrist joints (a, b, c) (1-based; J4-J6 of a 6-axis arm, J5-J7 of a
    7-axis one): dq_c = e_bc q_b + e_ac q_a, dq_b = e_ab q_a (dimensionless)."""
    js = tuple(int(j) for j in joints)
    if len(js) != 3 or js[1] != js[0] + 1 or js[2] != js[1] + 1 or js[0] < 1:
        raise ValueError(f"axis_coupling joints: the three consecutive joints of a spherical wrist (e.g. [5, 6, 7]), "
                         f"got {list(js)}")
    a, b, c = js

    def basis(kin, q, meta):
        dq = _zeros_dq(q, 3)
        dq[:, c - 1, 0], dq[:, c - 1, 1], dq[:, b - 1, 2] = q[:, b - 1], q[:, a - 1], q[:, a - 1]
        return Basis(dq=dq)
    return Effect("axis_coupling", (a, b, c), (f"e{b}{c}", f"e{a}{c}", f"e{a}{b}"), "1", basis,
                  typical=(4e-3, 2e-3, 2e-3))


def registration_drift(clock: str = "t_s", degree: int = 1, span: float = 3600.0) -> Effect:
    """Drift of the tracker against the robot base: dp = sum_k u^k (v_k + w_k x p) in the tracker frame, u =
    clock / span with ``clock`` "t_s" (time since the start, s) or "order" (position in the measurement sequence),
    k = 1..``degree``; v_k in mm, w_k in rad (per span^k). Without the clock (a commanded target) it is zero: the
    model is the robot at the start of the run."""
    if clock not in ("t_s", "order"):
        raise ValueError(f"unknown drift clock {clock!r} (expected t_s or order)")

    def basis(kin, q, meta):
        from robocal.kinematics.models import smr_tracker
        u = meta.get(clock)
        dp = np.zeros((len(q), 3, 6 * degree))
        if u is None:
            return Basis(dp=dp)
        u = np.asarray(u, float) / float(span)
        p = smr_tracker(kin, q)
        screw = np.concatenate([np.broadcast_to(np.eye(3), (len(q), 3, 3)), -skew(p)], axis=2)
        for k in range(degree):
            dp[:, :, 6 * k:6 * k + 6] = (u ** (k + 1))[:, None, None] * screw
        return Basis(dp=dp)
    names = tuple(f"{c}{k + 1}" for k in range(degree) for c in ("vx", "vy", "vz", "wx", "wy", "wz"))
    typical = tuple(v for _ in range(degree) for v in (0.02, 0.015, 0.01, 7e-6, 5e-6, 5e-6))
    return Effect("registration_drift", (), names, "mm or rad per span^k", basis, typical=typical, needs=(clock,))


def track_straightness(degree: int = 2) -> Effect:
    """Straightness and flatness of a linear track's rails: the carriage leaves the line by
    sum_k (h_k e_h + v_k e_v) P_k(x), k = 2..``degree`` (Legendre polynomials of the travel x, -1..1 over the
    joint's limits; degrees 0 and 1 are the registration and the track's direction), e_h the horizontal and e_v the
    third direction across the track (vertical for a floor track); h_k, v_k in mm."""
    if int(degree) < 2:
        raise ValueError(f"track_straightness degree: 2 or more (1 is the track's direction), got {degree}")
    ks = tuple(range(2, int(degree) + 1))

    def basis(kin, q, meta):
        if kin.track is None:
            raise ValueError("track_straightness needs a chain with a linear track")
        lo, hi = np.degrees(kin.q_min_rad[0]), np.degrees(kin.q_max_rad[0])
        x = 2.0 * (np.degrees(q[:, 0]) - lo) / max(hi - lo, 1e-9) - 1.0
        across = track_across(kin.track)
        dp = np.zeros((len(q), 3, 2 * len(ks)))
        for m, k in enumerate(ks):
            P = np.polynomial.legendre.legval(x, np.eye(k + 1)[k])
            for a in range(2):
                dp[:, :, 2 * m + a] = P[:, None] * (kin.T_tracker_base[:3, :3] @ across[a])
        return Basis(dp=dp)
    names = tuple(f"{c}{k}" for k in ks for c in ("h", "v"))
    return Effect("track_straightness", (1,), names, "mm", basis, typical=tuple(0.05 for _ in names))


def track_across(track: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two unit directions across a track (base frame): horizontal (perpendicular to the track and to base z)
    and the third one (vertical for a horizontal track); base x instead of z for a vertical track."""
    u = np.asarray(track, float) / np.linalg.norm(track)
    h = np.cross([0.0, 0.0, 1.0], u)
    if np.linalg.norm(h) < 1e-6:
        h = np.cross([1.0, 0.0, 0.0], u)
    h /= np.linalg.norm(h)
    return h, np.cross(u, h)


# ---------------------------------------------------------------- use of the bases
EFFECT_ROWS = 8192      # rows per block of ``effect_state`` (the bases (N, n, K) of one block at a time)


def meta_rows(meta: Mapping, rows: slice) -> dict:
    """The metadata of the rows ``rows`` of ``meta`` (per-row arrays sliced) as the effects see them among all
    rows: the warm-up's reference temperature (the first row's) is kept (``temp_ref_c``)."""
    out = {k: v if v is None or np.ndim(v) == 0 else np.asarray(v)[rows] for k, v in meta.items()}
    if meta.get("temp_c") is not None and "temp_ref_c" not in meta:
        out["temp_ref_c"] = float(np.asarray(meta["temp_c"], float)[0])
    return out


def combine(q_rad: np.ndarray, bases, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint deviation dq (N, n) rad, link-length scale (N,) and tracker-frame displacement dp (N, 3) mm of
    effect bases [Basis, ...] at the points ``q_rad`` (N, n) with their parameter values [(K,), ...]."""
    q = np.atleast_2d(q_rad)
    dq, scale, dp = np.zeros(q.shape), np.ones(len(q)), np.zeros((len(q), 3))
    for b, v in zip(bases, values):
        v = np.asarray(v, float)
        if b.dq is not None:
            dq += b.dq @ v
        if b.scale is not None:
            scale += b.scale @ v
        if b.dp is not None:
            dp += b.dp @ v
    return dq, scale, dp


def effect_state(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``combine`` of ``effects`` [(Effect, values (K,)), ...] at the points ``q_rad`` with their metadata: dq
    (robot), scale (links), dp (a drift of the measurement, not of the robot). In row blocks of ``EFFECT_ROWS``."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    if len(q) <= EFFECT_ROWS:
        return combine(q, [eff.basis(kin, q, meta) for eff, _ in effects], [v for _, v in effects])
    dq, scale, dp = np.empty(q.shape), np.empty(len(q)), np.empty((len(q), 3))
    for s in range(0, len(q), EFFECT_ROWS):
        b = slice(s, s + EFFECT_ROWS)
        dq[b], scale[b], dp[b] = effect_state(kin, q[b], meta_rows(meta, b), effects)
    return dq, scale, dp


def apply_effects(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """Exact SMR positions in the tracker frame (N, 3) mm of a robot with geometry ``kin`` and the
    given ``[(Effect, params (K,)), ...]``."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    dq, scale, dp = effect_state(kin, q, meta, effects)
    c = chain(kin, q + dq, a=kin.a_mm * scale[:, None], d=kin.d_mm * scale[:, None], full=False, axes=False)
    p_base = transform_points(c.T_base_flange, kin.p_flange_smr_mm)
    return transform_points(kin.T_tracker_base, p_base) + dp


def effect_regressor(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effect: Effect,
                     jacobian: tuple | None = None, basis: Basis | None = None) -> np.ndarray:
    """Linearised tracker-frame displacement per unit effect parameter, (N, 3, K) mm (``basis``: the effect's
    basis at these points when already computed)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    _, J = identification_jacobian(kin, q) if jacobian is None else jacobian
    layout = ParamLayout.of(kin)
    b = effect.basis(kin, q, meta) if basis is None else basis
    out = np.zeros((len(q), 3, effect.k))
    if b.dq is not None:
        out += np.einsum("nij,njk->nik", joint_motion_columns(kin, J), b.dq)
    if b.scale is not None:
        grow = sum(J[:, :, c] * (kin.d_mm[i] if k == 1 else kin.a_mm[i])
                   for c, i, k in layout.joint_cols if k in (1, 2))
        out += grow[:, :, None] * b.scale[:, None, :]
    if b.dp is not None:
        out += b.dp
    return out


def every_effect(n_joints: int = 6) -> tuple[Effect, ...]:
    """One instance of every library effect with its default joints (tests of the bases)."""
    effs = [joint_compliance(), joint_compliance(form="levers", n_joints=n_joints),
            joint_compliance(form="links", n_joints=n_joints), payload_deflection()]
    effs += [gear_cyclic(j) for j in range(1, min(n_joints, 6) + 1)]
    effs += [backlash(tuple(range(1, min(n_joints, 6) + 1))), readback_lag((1, 2, 3), (2,)), thermal_drift()]
    if n_joints >= 6:
        effs.append(axis_coupling())
    effs += [registration_drift(), registration_drift("order", 2, 100.0)]
    return tuple(effs)


FACTORY_KEYS = {"joint_compliance": {"joints", "form", "link_masses_kg", "payload_cog_flange_mm", "gravity_base"},
                "payload_deflection": {"joints", "payload_cog_flange_mm", "gravity_base"},
                "gear_cyclic": {"joint", "harmonics"}, "backlash": {"joints"},
                "readback_lag": {"joints", "memory_joints"}, "thermal_drift": {"tau_s", "joints"},
                "axis_coupling": {"joints"}, "registration_drift": {"clock", "degree", "span"},
                "track_straightness": {"degree"}}


def by_name(name: str, n_joints: int = 6, **kwargs) -> Effect:
    """Effect factory by name (the names of the JSON contract) with its keyword options (``FACTORY_KEYS``).
    ValueError names an unknown effect or option."""
    factories = {"joint_compliance": lambda **kw: joint_compliance(n_joints=n_joints, **kw),
                 "payload_deflection": payload_deflection,
                 "gear_cyclic": lambda **kw: gear_cyclic(kw.pop("joint", 1), **kw),
                 "backlash": backlash, "readback_lag": readback_lag, "thermal_drift": thermal_drift,
                 "axis_coupling": axis_coupling, "registration_drift": registration_drift,
                 "track_straightness": track_straightness}
    if name not in factories:
        raise ValueError(f"unknown effect {name!r} (expected one of: {', '.join(MODEL_EFFECTS)})")
    unknown = sorted(set(kwargs) - FACTORY_KEYS[name])
    if unknown:
        raise ValueError(f"effect {name!r} has no option {unknown[0]!r} (expected one of: "
                         f"{', '.join(sorted(FACTORY_KEYS[name])) or 'none'})")
    return factories[name](**kwargs)
