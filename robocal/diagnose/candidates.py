"""The candidate library: each effect as groups of regressor columns (a joint-space basis ``dq`` and/or a
tracker-frame basis ``dp``), with the metadata checks that decide whether the data can reveal it, and the
reference-nest drift test (``nest_drift``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy import stats

from ..effects import G_MM_S2
from ..frames import skew
from ..kinematics import Kinematics, ParamLayout, chain
from .records import DiagnosisOptions, NestReadings, moves_from_order


TIME_EFFECTS = ("thermal_drift", "registration_drift")


ELASTIC_CLASS = ("gravity-elastic class: joint compliance, link bending and base compliance give nearly the same "
                 "position signature with one SMR (orientation data or loads in different directions separate them)")


@dataclass(frozen=True, eq=False)
class Group:
    """Columns of one candidate sub-model: joint-space basis ``dq`` (N, n, k) rad per unit parameter and/or
    tracker-frame basis ``dp`` (N, 3, k) mm per unit parameter. ``limit`` (k,) max plausible |parameter|;
    ``dq_limit`` max plausible implied joint deflection over the data (rad)."""
    label: str
    joints: tuple[int, ...]
    names: tuple[str, ...]
    dq: np.ndarray | None = None
    dp: np.ndarray | None = None
    limit: np.ndarray | float = np.inf
    dq_limit: float = 2e-3
    u: np.ndarray | None = None          # (N,) per-point scale of ``base`` (time profiles): X = u * X_base
    base: "Group | None" = None

    @property
    def k(self) -> int:
        return len(self.names)

    def scaled(self, u: np.ndarray) -> "Group":
        """This group times a per-point profile u (N,): its regressor is u times this one's (exactly, since the
        whitening is per point), which lets the scoring whiten the base once for all profiles."""
        return Group(self.label, self.joints, self.names, None if self.dq is None else u[:, None, None] * self.dq,
                     None if self.dp is None else u[:, None, None] * self.dp, self.limit, self.dq_limit, u, self)


@dataclass(frozen=True, eq=False)
class Profile:
    """One variant of a candidate (time effects: one per time profile)."""
    label: str
    groups: tuple[Group, ...]


@dataclass(frozen=True, eq=False)
class Candidate:
    name: str
    joints: tuple[int, ...]
    profiles: tuple[Profile, ...] = ()
    reason: str = ""                    # why the data cannot reveal it ("" = diagnosable)
    notes: tuple[str, ...] = ()
    extends: bool = False               # the unselected groups of an accepted candidate
    veto: str = ""                      # a gate that rules it out whatever the fit says (e.g. direct comparison)
    info: dict = field(default_factory=dict)   # extra evidence (direct comparisons, nest drift)

    @property
    def key(self) -> str:
        return f"{self.name}:J{self.joints[0]}" if self.name == "gear_cyclic" else self.name

    @property
    def time_effect(self) -> bool:
        return self.name in TIME_EFFECTS

    @property
    def scan(self) -> int:
        """Extra parameters spent on choosing the profile: the time constant and the shape of a warm-up curve
        count as one each."""
        return 2 if len(self.profiles) > 2 else (1 if len(self.profiles) == 2 else 0)

    def rest(self, profile: "Profile", used) -> "Candidate | None":
        """The same candidate restricted to ``profile``'s groups not in ``used`` (None if nothing is left)."""
        left = tuple(g for g in profile.groups if all(g is not u for u in used))
        return Candidate(self.name, self.joints, (Profile(profile.label, left),), notes=self.notes,
                         extends=True, info=self.info) if left else None


def _torque_per_kg(axis_j, origin_j, P):
    """Gravity torque about a joint axis of 1 kg at P (N, 3) mm, N·m/kg; gravity is -z of the base frame."""
    h = np.cross(np.array([0.0, 0.0, 1.0]), axis_j)
    return -G_MM_S2 * np.einsum("nk,nk->n", h, P - origin_j) / 1000.0


def _independent(cols: np.ndarray, rows: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """Indices of columns of cols (N, m) that are linearly independent on ``rows`` (greedy Gram-Schmidt)."""
    A = cols[rows]
    keep, Q = [], np.zeros((len(rows), 0))
    for j in range(A.shape[1]):
        c = A[:, j]
        nrm = np.linalg.norm(c)
        if nrm < 1e-12:
            continue
        c = c / nrm
        r = c - Q @ (Q.T @ c)
        if np.linalg.norm(r) > tol:
            keep.append(j)
            Q = np.column_stack([Q, r / np.linalg.norm(r)])
    return np.array(keep, int)


def gravity_levers(kin: Kinematics, q_rad: np.ndarray, joint: int) -> tuple[np.ndarray, list[str]]:
    """Gravity torque per kg (N, m) about ``joint`` (1-based) of every downstream joint point, the flange and a
    point beside the next link: any lumped mass fixed on those links loads the joint by a combination of them."""
    c = chain(kin, q_rad, full=False)
    n = kin.n
    j = joint - 1
    flange = c.T_base_flange[:, :3, 3]
    pts = [(f"o{i + 1}", c.origin[:, i]) for i in range(j + 1, n)] + [("flange", flange)]
    nxt = c.origin[:, j + 1] if j + 1 < n else flange
    pts.append(("lateral", c.origin[:, j] + np.cross(c.axis[:, j], nxt - c.origin[:, j])))
    cols = np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], P) for _, P in pts], axis=1)
    return cols, [name for name, _ in pts]


def payload_levers(kin: Kinematics, q_rad: np.ndarray, joint: int, payload_kg: np.ndarray) -> np.ndarray:
    """Payload gravity torque (N, 2) N·m about ``joint`` for a payload at the flange and 100 mm along the tool
    axis (any centre of mass on the tool axis is a combination of the two)."""
    c = chain(kin, q_rad, full=False)
    j = joint - 1
    flange = c.T_base_flange[:, :3, 3]
    tip = flange + 100.0 * c.T_base_flange[:, :3, 2]
    return np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], P) for P in (flange, tip)], axis=1) \
        * np.asarray(payload_kg, float)[:, None]


def arm_mass_kg(kin: Kinematics) -> float:
    """Moving mass of an arm of this size (kg): about 25 kg at 0.58 m reach, growing with reach^2.5 (the size
    law of industrial 6-axis arms from 0.5 to 3 m reach)."""
    return 25.0 * (robot_reach_mm(kin) / 580.0) ** 2.5


def robot_reach_mm(kin: Kinematics) -> float:
    """Reach from the shoulder: sum of the link lengths after J1 (mm)."""
    return float(np.sum(np.hypot(kin.a_mm[1:], kin.d_mm[1:])) + np.linalg.norm(kin.p_flange_smr_mm))


def physical_torque_nm(kin: Kinematics, q_rad: np.ndarray, payload_kg: np.ndarray | None, arm: bool = True
                       ) -> np.ndarray:
    """Gravity torque (N, n) N*m about every joint of a physical lumped-mass model from the robot's size: the
    moving mass (``arm_mass_kg``) shared over the links after J1 in proportion to their lengths, each at its
    link's midpoint, plus the payload at the flange. Gravity is -z of the base frame."""
    c = chain(kin, q_rad, full=False)
    N, n = np.shape(q_rad)
    o = np.concatenate([c.origin, c.T_base_flange[:, None, :3, 3]], axis=1)
    mid = 0.5 * (o[:, :-1] + o[:, 1:])
    length = np.hypot(kin.a_mm, kin.d_mm)
    length[0] = 0.0
    m = arm_mass_kg(kin) * length / max(float(length.sum()), 1e-9) if arm else np.zeros(n)
    pay = np.zeros(N) if payload_kg is None else np.asarray(payload_kg, float)
    tau = np.zeros((N, n))
    for j in range(n):
        t_links = np.stack([_torque_per_kg(c.axis[:, j], c.origin[:, j], mid[:, i]) for i in range(j, n)], axis=1)
        tau[:, j] = t_links @ m[j:] + _torque_per_kg(c.axis[:, j], c.origin[:, j], o[:, -1]) * pay
    return tau


def direct_lag(q_read_rad: np.ndarray, qc_rad: np.ndarray, move_rad: np.ndarray, prev_rad: np.ndarray) -> dict:
    """Read-back minus commanded joints regressed per joint on [1, last move, move before]: the lag (deg/deg),
    its t value, the memory term and the correlation of the difference with the move."""
    d = np.asarray(q_read_rad, float) - np.asarray(qc_rad, float)
    out = {}
    for j in range(d.shape[1]):
        ok = np.isfinite(d[:, j]) & np.isfinite(move_rad[:, j])
        A = np.column_stack([np.ones(ok.sum()), move_rad[ok, j], prev_rad[ok, j]])
        y = d[ok, j]
        if ok.sum() < 10 or np.ptp(move_rad[ok, j]) <= 0:
            continue
        beta, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ beta
        s2 = float(r @ r) / max(len(y) - 3, 1)
        cov = s2 * np.linalg.pinv(A.T @ A)
        se = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        corr = float(np.corrcoef(y, move_rad[ok, j])[0, 1]) if np.std(y) > 0 else 0.0
        out[j + 1] = {"lag_deg_per_deg": float(beta[1]), "t": float(beta[1] / se[1]),
                      "memory_deg_per_deg": float(beta[2]), "t_memory": float(beta[2] / se[2]),
                      "offset_deg": float(np.degrees(beta[0])), "std_deg": float(np.degrees(np.std(y))),
                      "correlation_with_move": corr}
    return out


def _dq_group(label, joint_cols: dict, names, n, N, joints, **kw) -> Group:
    """Group whose columns act on single joints: joint_cols {joint (1-based): (N, k_j) array}."""
    k = sum(a.shape[1] for a in joint_cols.values())
    dq = np.zeros((N, n, k))
    at = 0
    for jt, a in joint_cols.items():
        dq[:, jt - 1, at:at + a.shape[1]] = a
        at += a.shape[1]
    return Group(label, tuple(joints), tuple(names), dq=dq, **kw)


def _payload_varies(payload, rows) -> bool:
    if payload is None:
        return False
    values = np.unique(np.round(np.asarray(payload, float)[rows], 3))
    return len(values) >= 2


def _compliance(kin, q, meta, rows, opt, payload_only: bool) -> Candidate:
    N, n = q.shape
    payload = meta.get("payload_kg")
    varies = _payload_varies(payload, rows)
    name = "payload_deflection" if payload_only else "joint_compliance"
    joints = tuple(j for j in opt.compliance_joints if 2 <= j <= n)
    if payload_only and not varies:
        why = "no payload logged" if payload is None else "one payload only"
        return Candidate(name, joints, reason=f"{why}: a payload-dependent deflection cannot be told from "
                                              "geometry and link-mass compliance")
    groups, shape = [], []
    tau = physical_torque_nm(kin, q, None if payload is None else np.asarray(payload, float), arm=not payload_only)
    for jt in joints:
        groups.append(_dq_group(f"J{jt}", {jt: tau[:, jt - 1:jt]}, (f"c{jt}",), n, N, (jt,), dq_limit=np.inf))
        parts, names = [], []
        if not payload_only:
            lev, labels = gravity_levers(kin, q, jt)
            parts.append(lev)
            names += [f"c{jt}_{lb}" for lb in labels]
        if varies:
            parts.append(payload_levers(kin, q, jt, payload))
            names += [f"c{jt}_payload_flange", f"c{jt}_payload_tool"]
        cols = np.concatenate(parts, axis=1)
        t = tau[rows, jt - 1]
        cols = cols - np.outer(tau[:, jt - 1], cols[rows].T @ t / max(float(t @ t), 1e-300))   # beyond the physical
        keep = _independent(cols, rows, 1e-2)
        if len(keep):
            shape.append(_dq_group(f"J{jt} mass distribution", {jt: cols[:, keep]}, tuple(names[i] for i in keep),
                                   n, N, (jt,), dq_limit=np.inf))
    groups += shape
    notes = [ELASTIC_CLASS] if not payload_only else []
    if not payload_only and not varies:
        notes.append("one payload only: compliance is partly confounded with geometry (log a second payload)")
    return Candidate(name, joints, (Profile("gravity torque", tuple(groups)),), notes=tuple(notes),
                     info={"torque_nm": tau, "stiffness_min_nm_per_rad": stiffness_floor_nm_per_rad(kin)})


def stiffness_floor_nm_per_rad(kin: Kinematics) -> float:
    """Lowest plausible joint stiffness of an arm of this size (N*m/rad): 2e4 x (reach in m)^3, about ten times
    softer than the main axes of industrial arms (stiffness grows with the cube of the size)."""
    return 2e4 * (robot_reach_mm(kin) / 1000.0) ** 3


def _gear(kin, q, joint, rows, opt) -> Candidate:
    N, n = q.shape
    qj = q[rows, joint - 1]
    span = np.degrees(qj.max() - qj.min())
    if span < opt.gear_min_span_deg:
        return Candidate("gear_cyclic", (joint,), reason=f"J{joint} covers only {span:.0f} deg: a cyclic error "
                                                         "cannot be told from its zero offset")
    groups = []
    for h in opt.harmonics:
        cols = np.stack([np.sin(h * q[:, joint - 1]), np.cos(h * q[:, joint - 1])], axis=1)
        groups.append(_dq_group(f"h{h}", {joint: cols}, (f"sin{h}", f"cos{h}"), n, N, (joint,),
                                limit=opt.gear_max_rad, dq_limit=opt.max_joint_deflection_rad))
    return Candidate("gear_cyclic", (joint,), (Profile("harmonics", tuple(groups)),))


def _backlash(kin, q, meta, rows, opt) -> Candidate:
    N, n = q.shape
    s = meta.get("approach")
    joints = tuple(range(1, n + 1))
    if s is None:
        return Candidate("backlash", joints, reason="no approach directions in the data")
    s = np.asarray(s, float)
    groups, constant = [], []
    for j in joints:
        sj = s[rows, j - 1]
        if min(np.sum(sj > 0), np.sum(sj < 0)) < max(opt.backlash_min_side, opt.backlash_min_side_fraction * len(rows)):
            constant.append(j)
            continue
        groups.append(_dq_group(f"J{j}", {j: 0.5 * s[:, j - 1:j]}, (f"b{j}",), n, N, (j,), limit=opt.backlash_max_rad,
                                dq_limit=opt.max_joint_deflection_rad))
    if not groups:
        return Candidate("backlash", joints, reason="approach directions never change (every joint is reached "
                                                    "from the same side)")
    notes = (f"approach direction constant on J{', J'.join(map(str, constant))}",) if constant else ()
    return Candidate("backlash", tuple(g.joints[0] for g in groups), (Profile("approach", tuple(groups)),),
                     notes=notes)


def _readback_lag(kin, q, meta, rows, opt) -> Candidate:
    """Read-back lag: the reported joint is off by lambda x (signed last move) [+ mu x (move before)]; the model
    input is corrected by dq = -lambda move (parameter -lambda, rad/rad). With commanded joints the difference is
    measured directly and decides which joints can carry it."""
    N, n = q.shape
    move, prev, qc = meta.get("move"), meta.get("prev_move"), meta.get("qc")
    joints = tuple(j for j in range(1, n + 1) if np.std(move[rows, j - 1]) > np.radians(opt.lag_min_move_std_deg))
    if not joints:
        return Candidate("readback_lag", tuple(range(1, n + 1)), reason="the joints hardly move between points")
    veto, direct = "", {}
    if qc is not None:
        qcm, qcp = moves_from_order(qc) if meta.get("move_cmd") is None else (meta["move_cmd"], meta["prev_cmd"])
        direct = direct_lag(q if meta.get("q_read") is None else meta["q_read"], qc, qcm, qcp)
        sig = tuple(j for j in joints if j in direct and abs(direct[j]["t"]) >= opt.lag_direct_min_t
                    and abs(direct[j]["lag_deg_per_deg"]) >= opt.lag_direct_min_deg_per_deg)
        if not sig:
            veto = ("commanded and read-back joints agree: no lag proportional to the move (direct comparison, "
                    f"|t| < {opt.lag_direct_min_t:g} on every joint)")
        else:
            joints = sig
    kw = {"limit": opt.lag_max, "dq_limit": np.inf}          # judged on the lag itself (deg/deg), not on move x lag
    groups = [_dq_group(f"J{j}", {j: move[:, j - 1:j]}, (f"lag{j}",), n, N, (j,), **kw) for j in joints]
    groups += [_dq_group(f"J{j} memory", {j: prev[:, j - 1:j]}, (f"lag{j}_memory",), n, N, (j,), **kw)
               for j in joints]
    return Candidate("readback_lag", joints, (Profile("signed last move", tuple(groups)),), veto=veto,
                     info={"direct_comparison": direct} if direct else {})


def _time_profiles(meta, rows, opt) -> tuple[list[tuple[str, np.ndarray]], str]:
    """[(label, u (N,) in [0, 1])] time profiles, or a reason why none exists."""
    t, temp = meta.get("t_s"), meta.get("temp_c")
    out = []
    if temp is not None:
        temp = np.asarray(temp, float)
        rise = temp - temp[rows].min()
        if np.ptp(temp[rows]) >= opt.temp_min_span_c:
            out.append(("temperature", rise / np.max(np.abs(rise[rows]))))
    if t is not None:
        t = np.asarray(t, float)
        span = np.ptp(t[rows])
        if span >= opt.time_min_span_s:
            t0 = t - t[rows].min()
            out.append(("linear in time", t0 / np.max(t0[rows])))
            for beta in opt.shape_grid:
                for tau in opt.tau_grid_h:
                    u = 1.0 - np.exp(-(np.maximum(t0, 0.0) / (tau * 3600.0)) ** beta)
                    shape = "" if beta == 1.0 else f", shape {beta:g}"
                    out.append((f"warm-up 1-exp(-(t/tau)^b) tau {tau:g} h{shape}", u / np.max(u[rows])))
        elif not out:
            return [], f"the data span only {span / 60:.0f} min: too short to reveal drift"
    if not out:
        return [], "no timestamps or temperatures in the data"
    return out, ""


def _thermal(kin, q, meta, J, layout, rows, opt) -> Candidate:
    """Warm-up u(t) x {uniform growth of every link length, growth of single links, zero drift of J2/J3}.
    The base-column length d1 alone is left out of the single-link groups: its growth is a rigid vertical
    drift, which is registration drift's signature; it enters through the uniform growth."""
    N, n = q.shape
    profiles, why = _time_profiles(meta, rows, opt)
    joints = tuple(j for j in opt.thermal_zero_joints if j <= n)
    if why:
        return Candidate("thermal_drift", joints, reason=why)
    lengths = [(c, f"{'da'[k - 1]}{i + 1}", (kin.d_mm if k == 1 else kin.a_mm)[i])
               for c, i, k in layout.joint_cols
               if k in (1, 2) and abs((kin.d_mm if k == 1 else kin.a_mm)[i]) > opt.thermal_min_link_mm]
    uniform = sum(J[:, :, c] * L for c, _, L in lengths)
    single = [(c, name, L) for c, name, L in lengths if name != "d1"]
    bases = [Group("uniform growth", (), ("growth_all",), dp=uniform[:, :, None], limit=opt.growth_max)]
    bases += [Group(f"growth {name}", (), (f"growth_{name}",), dp=(J[:, :, c] * L)[:, :, None],
                    limit=opt.growth_max)
              for c, name, L in single]
    bases += [_dq_group(f"zero J{j}", {j: np.ones((N, 1))}, (f"zero_drift{j}",), n, N, (j,),
                         limit=opt.zero_drift_max_rad, dq_limit=opt.max_joint_deflection_rad)
              for j in joints]
    out = [Profile(label, tuple(b.scaled(u) for b in bases)) for label, u in profiles]
    return Candidate("thermal_drift", joints, tuple(out))


def _registration(kin, q, meta, p_model, rows, opt) -> Candidate:
    drift = meta.get("nest_drift")
    info = {"nest_drift": drift} if drift else {}
    if drift and drift["ruled_out"]:
        return Candidate("registration_drift", (), veto=f"ruled out by the reference nests: {drift['summary']}",
                         info=info)
    if meta.get("t_s") is None:
        if drift and drift["detected"]:              # no timestamps: the measurement order carries the time
            x = np.asarray(meta["order"], float)
            x = (x - x[rows].min()) / max(np.ptp(x[rows]), 1e-9)
            profiles = [("linear in measurement order", x), ("quadratic in measurement order", x**2)]
        else:
            return Candidate("registration_drift", (), reason="no timestamps in the data"
                             + ("" if drift else " and no reference nests"), info=info)
    else:
        profiles, why = _time_profiles(meta, rows, opt)
        profiles = [(label, u) for label, u in profiles if label != "temperature"]
        if why or not profiles:
            return Candidate("registration_drift", (), reason=why or "no timestamps in the data", info=info)
    centre = p_model[rows].mean(axis=0)
    screw = np.concatenate([np.broadcast_to(np.eye(3), (len(q), 3, 3)), -skew(p_model - centre)], axis=2)
    names = ("vx", "vy", "vz", "wx", "wy", "wz")
    limit = np.array([opt.registration_max_mm] * 3 + [opt.registration_max_rad] * 3)
    bases = (Group("translation", (), names[:3], dp=screw[:, :, :3], limit=limit[:3]),
             Group("rotation", (), names[3:], dp=screw[:, :, 3:], limit=limit[3:]))
    out = [Profile(label, tuple(b.scaled(u) for b in bases)) for label, u in profiles]
    return Candidate("registration_drift", (), tuple(out), info=info)


def _coupling(kin, q, opt) -> Candidate:
    N, n = q.shape
    if n < 6:
        return Candidate("axis_coupling", (), reason="needs a 6-axis wrist")
    kw = {"limit": opt.coupling_max, "dq_limit": opt.coupling_max * np.max(np.abs(q[:, 3:5]))}
    groups = (_dq_group("e56", {6: q[:, 4:5]}, ("e56",), n, N, (5, 6), **kw),
              _dq_group("e46", {6: q[:, 3:4]}, ("e46",), n, N, (4, 6), **kw),
              _dq_group("e45", {5: q[:, 3:4]}, ("e45",), n, N, (4, 5), **kw))
    notes = ()
    off_axis = float(np.hypot(*kin.p_flange_smr_mm[:2]))
    if off_axis < opt.coupling_min_off_axis_mm:
        notes = (f"SMR only {off_axis:.0f} mm off the J6 axis: J6 coupling is nearly invisible",)
    return Candidate("axis_coupling", (4, 5, 6), (Profile("wrist", groups),), notes=notes)


def build_candidates(kin: Kinematics, q_rad: np.ndarray, meta: Mapping, rows: np.ndarray, J: np.ndarray,
                     p_model: np.ndarray, options: DiagnosisOptions = DiagnosisOptions()) -> list[Candidate]:
    """The candidate library evaluated at ``kin`` for all rows; ``rows`` (indices) are the calibration rows
    used to judge whether the metadata vary enough. ``J`` (N, 3, P) identification Jacobian, ``p_model`` (N, 3)."""
    layout = ParamLayout.of(kin)
    n = kin.n
    cands = [_compliance(kin, q_rad, meta, rows, options, False), _compliance(kin, q_rad, meta, rows, options, True)]
    cands += [_gear(kin, q_rad, j, rows, options) for j in range(1, n + 1)]
    cands += [_backlash(kin, q_rad, meta, rows, options), _readback_lag(kin, q_rad, meta, rows, options), _thermal(kin, q_rad, meta, J, layout, rows, options),
              _coupling(kin, q_rad, options), _registration(kin, q_rad, meta, p_model, rows, options)]
    return cands


def nest_drift(nests: NestReadings, floor_mm: float, alpha: float = 1e-3, ruled_out_ratio: float = 1.5
               ) -> dict | None:
    """Tracker drift seen by reference nests: each nest's readings (minus their mean) fitted with a quadratic in
    time (or in measurement order without timestamps); pooled F test against a constant; the drift is the largest
    3-D excursion of the fitted trends. ``ruled_out`` when not detected and its upper bound (trend + 3 standard
    errors) is below 1.5 x the noise floor (a drift range that adds less than 0.45 x the floor in RMS). None with fewer than 3 readings of any nest."""
    ids = np.asarray(nests.nest_id)
    x_all = np.asarray(nests.t_s if nests.t_s is not None else nests.order, float)
    span = float(np.ptp(x_all)) if len(x_all) else 0.0
    if span <= 0:
        return None
    rss0 = rss1 = 0.0
    dof1, k_extra, excursion, m_min = 0, 0, 0.0, np.inf
    slopes = []
    for nid in np.unique(ids):
        sel = ids == nid
        if sel.sum() < 4:
            continue
        x = (x_all[sel] - x_all.min()) / span
        p = np.asarray(nests.p_mm)[sel] - np.asarray(nests.p_mm)[sel].mean(axis=0)
        A = np.column_stack([np.ones(len(x)), x - x.mean(), (x - x.mean()) ** 2])
        beta, *_ = np.linalg.lstsq(A, p, rcond=None)
        trend = A[:, 1:] @ beta[1:]
        r = p - A @ beta
        rss0 += float(np.sum(p**2))
        rss1 += float(np.sum(r**2))
        dof1 += 3 * (len(x) - 3)
        k_extra += 6
        excursion = max(excursion, float(np.max(np.linalg.norm(trend - trend[:, None].mean(axis=0), axis=1))) * 2.0)
        m_min = min(m_min, len(x))
        xc = x - x.mean()
        slopes.append(xc @ p / max(float(xc @ xc), 1e-300))      # linear drift over the run (mm per run)
    if k_extra == 0 or dof1 <= 0:
        return None
    sigma = math.sqrt(rss1 / dof1)
    F = ((rss0 - rss1) / k_extra) / max(rss1 / dof1, 1e-300)
    p_value = float(stats.f.sf(F, k_extra, dof1))
    linear = float(np.linalg.norm(np.mean(slopes, axis=0)))        # common to all nests (the tracker moved)
    se = sigma * math.sqrt(12.0 / m_min) / math.sqrt(len(slopes))
    detected = p_value < alpha
    if not detected:
        excursion = linear
    bound = linear + 2.0 * math.sqrt(3.0) * se
    ruled_out = (not detected) and bound < ruled_out_ratio * floor_mm   # a range of 1.5 x floor is < 0.45 x floor RMS
    basis = "time" if nests.t_s is not None else "measurement order"
    summary = (f"nests moved {excursion:.3f} mm over the run (p = {p_value:.2g}, by {basis})" if detected else
               f"nests stable within {bound:.3f} mm (drift {excursion:.3f} mm, p = {p_value:.2g}, by {basis})")
    return {"detected": detected, "ruled_out": ruled_out, "drift_mm": excursion, "upper_bound_mm": bound,
            "p_value": p_value, "nest_sigma_mm": sigma, "n_nests": int(k_extra // 6), "basis": basis,
            "summary": summary}
