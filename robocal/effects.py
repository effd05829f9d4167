"""Non-geometric effect models (effects.md §2), each linear in its parameters.

An effect maps joint angles ``q_rad (N, n)`` and per-point metadata to a *basis* with K columns:

* ``dq``    (N, n, K): joint-angle deviation per unit parameter (rad),
* ``scale`` (N, K):    relative growth of every link length a_i, d_i per unit parameter,
* ``dp``    (N, 3, K): SMR displacement in the tracker frame per unit parameter (mm).

The same basis both *simulates* a robot (``apply_effects``: exact FK with ``q + dq`` and scaled links)
and *extends* a model as extra parameters (``effect_regressor``: the linearised tracker-frame columns).
Metadata keys (all optional, arrays of N): ``t_s`` time since the campaign start (s), ``temp_c``,
``payload_kg``, ``approach`` (N, n) sign of the last motion of each joint (+1/-1/0).
Joint numbers in names and ``joints`` are 1-based.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from .kinematics import Kinematics, ParamLayout, chain, identification_jacobian
from .frames import skew, transform_points

G_MM_S2 = 9.80665
EFFECT_NAMES = ("joint_compliance", "payload_deflection", "gear_cyclic", "backlash", "readback_lag", "thermal_drift",
                "axis_coupling", "registration_drift")     # every effect the diagnosis names, in report order
SIMULATED_EFFECTS = tuple(name for name in EFFECT_NAMES if name != "readback_lag")   # what ``by_name`` builds
# the effects a calibrated model may carry as parameters (read-back lag is a joint-set choice, registration drift
# the nests' drift model)
MODEL_EFFECTS = tuple(name for name in EFFECT_NAMES if name not in ("readback_lag", "registration_drift"))


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


# ---------------------------------------------------------------- gravity torques
def gravity_torques(kin: Kinematics, q_rad: np.ndarray, link_masses_kg, payload_kg) -> np.ndarray:
    """Gravity torque about each joint axis (N, n) in N·m from lumped masses at the midpoint of each
    link (joint origin i -> joint origin i+1, the last one -> flange) and a payload at the SMR.
    Gravity is -z of the base frame."""
    c = chain(kin, q_rad)
    N, n = q_rad.shape
    o = np.concatenate([c.origin, c.T_base_flange[:, None, :3, 3]], axis=1)      # (N, n+1, 3)
    centres = 0.5 * (o[:, :-1] + o[:, 1:])                                       # (N, n, 3)
    p_smr = transform_points(c.T_base_flange, kin.p_flange_smr_mm)
    masses = np.broadcast_to(np.asarray(link_masses_kg, float), (N, n))
    force = np.array([0.0, 0.0, -G_MM_S2])                                       # per kg, N
    tau = np.zeros((N, n))
    for j in range(n):
        lever = centres[:, j:] - c.origin[:, j:j + 1]                             # links j..n-1 hang on joint j
        t_links = np.einsum("nmk,nk->nm", np.cross(lever, force), c.axis[:, j]) * masses[:, j:]
        t_pay = np.einsum("nk,nk->n", np.cross(p_smr - c.origin[:, j], force), c.axis[:, j]) * np.asarray(payload_kg, float)
        tau[:, j] = (t_links.sum(axis=1) + t_pay) / 1000.0                        # N·mm -> N·m
    return tau


DEFAULT_LINK_MASSES_KG = (0.0, 35.0, 40.0, 12.0, 4.0, 1.0)


def _link_masses(n, masses):
    m = np.zeros(n)
    src = np.asarray(masses, float)
    m[: min(n, len(src))] = src[: min(n, len(src))]
    return m


# ---------------------------------------------------------------- effect factories
def joint_compliance(joints=(2, 3), form: str = "gravity", link_masses_kg=DEFAULT_LINK_MASSES_KG) -> Effect:
    """Joint compliance under gravity.

    ``gravity``: dq_j = c_j * tau_j(q, payload), c_j compliance in rad/(N·m), tau from lumped masses + payload.
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

    def basis(kin, q, meta):
        tau = gravity_torques(kin, q, _link_masses(kin.n, link_masses_kg), _meta(meta, "payload_kg", len(q)))
        dq = _zeros_dq(q, len(joints))
        for k, j in enumerate(joints):
            dq[:, j - 1, k] = tau[:, j - 1]
        return Basis(dq=dq)
    typical = {1: 2e-7, 2: 3.3e-7, 3: 6.7e-7}
    return Effect("joint_compliance", tuple(joints), tuple(f"c{j}" for j in joints), "rad/(N*m)", basis,
                  typical=tuple(typical.get(j, 3e-6) for j in joints))


def payload_deflection(joints=(2, 3)) -> Effect:
    """Deflection from the payload's gravity torque only: dq_j = c_j * tau_payload_j (rad/(N·m))."""
    def basis(kin, q, meta):
        tau = gravity_torques(kin, q, np.zeros(kin.n), _meta(meta, "payload_kg", len(q)))
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


def warmup(meta, n, tau_s):
    """Thermal state u in [0, 1): from temperature rise when logged (per K), else 1 - exp(-t/tau)."""
    temp = meta.get("temp_c")
    if temp is not None:
        temp = np.asarray(temp, float)
        return temp - temp[0]
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


def axis_coupling() -> Effect:
    """Wrist coupling / ratio error: dq6 = e56 q5 + e46 q4, dq5 = e45 q4 (dimensionless)."""
    def basis(kin, q, meta):
        dq = _zeros_dq(q, 3)
        dq[:, 5, 0], dq[:, 5, 1], dq[:, 4, 2] = q[:, 4], q[:, 3], q[:, 3]
        return Basis(dq=dq)
    return Effect("axis_coupling", (4, 5, 6), ("e56", "e46", "e45"), "1", basis, typical=(4e-3, 2e-3, 2e-3))


def registration_drift() -> Effect:
    """Tracker-to-base drift linear in time: dp = t_h * (v + w x p) in the tracker frame (mm/h, rad/h)."""
    def basis(kin, q, meta):
        t_h = _meta(meta, "t_s", len(q)) / 3600.0
        from .kinematics import smr_tracker
        p = smr_tracker(kin, q)
        dp = np.zeros((len(q), 3, 6))
        dp[:, :, :3] = np.eye(3)
        dp[:, :, 3:] = -skew(p)
        return Basis(dp=dp * t_h[:, None, None])
    return Effect("registration_drift", (), ("vx", "vy", "vz", "wx", "wy", "wz"), "mm/h or rad/h", basis,
                  typical=(0.02, 0.015, 0.01, 7e-6, 5e-6, 5e-6), needs=("t_s",))


# ---------------------------------------------------------------- use of the bases
def apply_effects(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effects) -> np.ndarray:
    """Exact SMR positions in the tracker frame (N, 3) mm of a robot with geometry ``kin`` and the
    given ``[(Effect, params (K,)), ...]``."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    dq, scale, dp = np.zeros_like(q), np.ones(len(q)), np.zeros((len(q), 3))
    for eff, params in effects:
        b = eff.basis(kin, q, meta)
        params = np.asarray(params, float)
        if b.dq is not None:
            dq += b.dq @ params
        if b.scale is not None:
            scale += b.scale @ params
        if b.dp is not None:
            dp += b.dp @ params
    c = chain(kin, q + dq, a=kin.a_mm * scale[:, None], d=kin.d_mm * scale[:, None])
    p_base = transform_points(c.T_base_flange, kin.p_flange_smr_mm)
    return transform_points(kin.T_tracker_base, p_base) + dp


def effect_regressor(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, effect: Effect,
                     jacobian: tuple | None = None) -> np.ndarray:
    """Linearised tracker-frame displacement per unit effect parameter, (N, 3, K) mm."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    _, J = identification_jacobian(kin, q) if jacobian is None else jacobian
    layout = ParamLayout.of(kin)
    b = effect.basis(kin, q, meta)
    out = np.zeros((len(q), 3, effect.k))
    theta_cols = [c for c, i, k in layout.joint_cols if k == 0]
    if b.dq is not None:
        out += np.einsum("nij,njk->nik", J[:, :, theta_cols], b.dq)
    if b.scale is not None:
        grow = sum(J[:, :, c] * (kin.d_mm[i] if k == 1 else kin.a_mm[i])
                   for c, i, k in layout.joint_cols if k in (1, 2))
        out += grow[:, :, None] * b.scale[:, None, :]
    if b.dp is not None:
        out += b.dp
    return out


def library(n_joints: int = 6) -> tuple[Effect, ...]:
    """The candidate effects of the diagnosis library with their default joints."""
    effs = [joint_compliance(), payload_deflection()]
    effs += [gear_cyclic(j) for j in range(1, min(n_joints, 6) + 1)]
    effs += [backlash(tuple(range(1, min(n_joints, 6) + 1))), thermal_drift()]
    if n_joints >= 6:
        effs.append(axis_coupling())
    effs.append(registration_drift())
    return tuple(effs)


def by_name(name: str, n_joints: int = 6, **kwargs) -> Effect:
    """Effect factory by name (the names of the JSON contract) with its default parameters."""
    factories = {"joint_compliance": joint_compliance, "payload_deflection": payload_deflection,
                 "gear_cyclic": lambda **kw: gear_cyclic(kw.pop("joint", 1), **kw),
                 "backlash": backlash, "thermal_drift": thermal_drift, "axis_coupling": axis_coupling,
                 "registration_drift": registration_drift}
    if name not in factories:
        raise ValueError(f"unknown effect {name!r} (expected one of: {', '.join(SIMULATED_EFFECTS)})")
    return factories[name](**kwargs)


# ---------------------------------------------------------------- alternative functional forms
# Used as *truths* by the self-check (robocal/selfcheck.py), so that the diagnosis is not only tested on the
# forms its own candidates use: lumped masses with off-line centres of mass and an offset payload, other warm-up
# curves with per-link growth, drifting registration with a settling curve.
def warmup_curve(t_s: np.ndarray, curve: str = "exp", tau_s: float = 2700.0, tau2_s: float | None = None,
                 mix: float = 0.5) -> np.ndarray:
    """Thermal state u(t) in [0, 1]: ``exp`` 1 - e^(-t/tau); ``two_exp`` mix of two such curves (tau, tau2);
    ``hyperbolic`` t / (t + tau); ``ramp`` min(t / tau, 1) (linear warm-up, then steady)."""
    t = np.maximum(np.asarray(t_s, float), 0.0)
    if curve == "exp":
        return 1.0 - np.exp(-t / tau_s)
    if curve == "two_exp":
        return mix * (1.0 - np.exp(-t / tau_s)) + (1.0 - mix) * (1.0 - np.exp(-t / (tau2_s or 4.0 * tau_s)))
    if curve == "hyperbolic":
        return t / (t + tau_s)
    if curve == "ramp":
        return np.minimum(t / tau_s, 1.0)
    raise ValueError(f"unknown warm-up curve {curve!r} (expected exp, two_exp, hyperbolic or ramp)")


def lumped_gravity_torques(kin: Kinematics, q_rad: np.ndarray, link_masses_kg, com_fraction=0.5,
                           com_lateral_mm=0.0, payload_kg=0.0, payload_com_flange_mm=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Gravity torque about each joint axis (N, n) N·m from one lumped mass per link and a payload.

    Link i runs from joint i's axis point to joint i+1's (the last to the flange); its centre of mass sits at
    ``com_fraction`` of the way along it and ``com_lateral_mm`` off it, perpendicular to the link in the plane
    normal to joint i's axis (so it is not on the link line). The payload's centre of mass is
    ``payload_com_flange_mm`` in the flange frame. Gravity is -z of the base frame."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    c = chain(kin, q, full=False)
    N, n = q.shape
    flange = c.T_base_flange[:, :3, 3]
    o = np.concatenate([c.origin, flange[:, None, :]], axis=1)
    link = o[:, 1:] - o[:, :-1]
    lat = np.cross(c.axis, link)
    norm = np.linalg.norm(lat, axis=2, keepdims=True)
    lat = np.where(norm > 1e-6, lat / np.maximum(norm, 1e-12), 0.0)
    f = np.broadcast_to(np.asarray(com_fraction, float), (n,))
    lateral = np.broadcast_to(np.asarray(com_lateral_mm, float), (n,))
    com = o[:, :-1] + f[None, :, None] * link + lateral[None, :, None] * lat
    p_pay = flange + np.einsum("nij,j->ni", c.T_base_flange[:, :3, :3], np.asarray(payload_com_flange_mm, float))
    masses = _link_masses(n, link_masses_kg)
    pay = np.broadcast_to(np.asarray(payload_kg, float), (N,))
    force = np.array([0.0, 0.0, -G_MM_S2])
    tau = np.zeros((N, n))
    for j in range(n):
        arm = com[:, j:] - c.origin[:, j:j + 1]
        t_links = np.einsum("nmk,nk->nm", np.cross(arm, force), c.axis[:, j]) @ masses[j:]
        t_pay = np.einsum("nk,nk->n", np.cross(p_pay - c.origin[:, j], force), c.axis[:, j]) * pay
        tau[:, j] = (t_links + t_pay) / 1000.0
    return tau


def lumped_compliance(joints=(2, 3), link_masses_kg=DEFAULT_LINK_MASSES_KG, com_fraction=0.5, com_lateral_mm=0.0,
                      payload_com_flange_mm=(0.0, 0.0, 0.0), name: str = "joint_compliance") -> Effect:
    """Joint compliance from lumped-mass gravity torques (``lumped_gravity_torques``): dq_j = c_j * tau_j,
    c_j in rad/(N·m). With all link masses zero it is the payload-only deflection (``name`` payload_deflection)."""
    def basis(kin, q, meta):
        tau = lumped_gravity_torques(kin, q, link_masses_kg, com_fraction, com_lateral_mm,
                                     _meta(meta, "payload_kg", len(q)), payload_com_flange_mm)
        dq = _zeros_dq(q, len(joints))
        for k, j in enumerate(joints):
            dq[:, j - 1, k] = tau[:, j - 1]
        return Basis(dq=dq)
    return Effect(name, tuple(joints), tuple(f"c{j}" for j in joints), "rad/(N*m)", basis,
                  typical=tuple({2: 3.3e-7, 3: 6.7e-7}.get(j, 3e-6) for j in joints),
                  needs=("payload_kg",) if name == "payload_deflection" else ())


def thermal_warmup(length_growth, zero_drift_rad, curve: str = "exp", tau_s: float = 2700.0,
                   tau2_s: float | None = None, mix: float = 0.5) -> Effect:
    """Warm-up with per-link growth: a_i, d_i grow by ``length_growth[i] * u(t)`` (relative) and joint zeros drift
    by ``zero_drift_rad[i] * u(t)``, u = ``warmup_curve``. Exact (not linearised): one parameter, the scale of
    the whole displacement (1 = as given); its basis is the exact SMR displacement in the tracker frame."""
    from .kinematics import smr_tracker
    g = np.asarray(length_growth, float)
    z = np.asarray(zero_drift_rad, float)

    def basis(kin, q, meta):
        u = warmup_curve(_meta(meta, "t_s", len(q)), curve, tau_s, tau2_s, mix)[:, None]
        c = chain(kin, q, a=kin.a_mm * (1 + u * g), d=kin.d_mm * (1 + u * g), theta=kin.theta_rad + u * z, full=False)
        p = transform_points(kin.T_tracker_base, transform_points(c.T_base_flange, kin.p_flange_smr_mm))
        return Basis(dp=(p - smr_tracker(kin, q))[:, :, None])
    return Effect("thermal_drift", tuple(int(i) + 1 for i in np.flatnonzero(z)), ("scale",), "1", basis,
                  typical=(1.0,), needs=("t_s",))


def registration_drift_curve(v_mm, w_rad, curve: str = "linear", tau_s: float = 2700.0) -> Effect:
    """Tracker-to-base drift dp = u(t) * (v + w x p): ``linear`` u = t in hours (v mm/h, w rad/h), otherwise
    u = ``warmup_curve`` (a settling tripod: v, w are the final offsets). One parameter (scale, 1 = as given)."""
    from .kinematics import smr_tracker
    v, w = np.asarray(v_mm, float), np.asarray(w_rad, float)

    def basis(kin, q, meta):
        t = _meta(meta, "t_s", len(q))
        u = t / 3600.0 if curve == "linear" else warmup_curve(t, curve, tau_s)
        p = smr_tracker(kin, q)
        return Basis(dp=(u[:, None] * (v + np.cross(w, p)))[:, :, None])
    return Effect("registration_drift", (), ("scale",), "1", basis, typical=(1.0,), needs=("t_s",))
