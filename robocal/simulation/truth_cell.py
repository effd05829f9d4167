"""Independent truth generator for testing the diagnosis: a simulated robot cell written from the physics.

Nothing here uses the diagnosis (``robocal.diagnose``), the effect engine (``robocal.effects``) or the effect
bases of ``robocal.effects``, not even through a package ``__init__`` (``tests/robocal/test_diagnose_truth.py``
checks what importing this module loads): every effect is modelled as what happens in the machine, then the laser
tracker measures the SMR. Only the forward kinematics (``robocal.kinematics.models.chain``), the frames and the tracker
noise model are shared.

Physics (lengths mm, angles rad, torques N*m, time s):

* **geometry**: every DH parameter of the nominal model off by a random amount (alpha/theta 0.005-0.05 deg,
  a/d 0.05-0.5 mm, Hayati beta on J2); the tracker 2.5-4 m away in a random orientation; SMR 50-80 mm off the
  J6 axis, its nominal offset 0.5 mm wrong.
* **gravity compliance** (``joint_compliance``): link masses lumped at random centres of mass (random fraction
  along each link, random offsets beside and out of the link line), payload with a random centre of mass in the
  flange frame; the gravity torque about J2/J3 is summed over everything downstream (so the J2 torque depends
  on q3); the link deflects by torque / stiffness (N*m/rad).
* **payload deflection**: the same spring, but the arm's own weight is balanced (balancer): only the payload
  torque deflects the joints.
* **gear cyclic error**: link angle = motor angle / ratio + sum_h A_h sin(h q + phi_h), harmonics from
  {1}, {2}, {1,2}, {2,3}, {1,3} (harmonic 2 in most sets).
* **backlash**: the link lags the motor by a constant half-width b on the side of the last motion
  (q_link = q_cmd - b * sign(last move)); it saturates: it does not depend on the size of the move.
* **read-back lag**: the controller reports q_read = q_cmd + lambda * (last move) [+ mu * (move before)]:
  proportional to the signed move, no effect on where the link really is.
* **wrist coupling**: the J6 (J5) output turns with J5 (J4) through the wrist gears: q6 += e * q5.
* **thermal warm-up**: all link lengths grow by alpha_T * dT * (1 - exp(-t/tau)), encoder zeros of J2/J3 drift
  with the same curve (exact FK per point with the grown lengths).
* **reach-dependent J2 sag** (not in the library): J2 turns down (the TCP lowers) by an angle growing with the
  square of the horizontal reach (a stiffness that softens with the load's lever).
* **joint jitter** (not in the library): the read-back joints J1-J3 carry random noise above the encoder
  resolution (0.004 deg RMS, x scale): nothing in the pose predicts it.
* **registration drift**: the tracker stand creeps: a rigid screw (translation mm, rotation rad) growing
  linearly in time or settling exponentially.
* **measurement order**: poses are measured in random order (calibration and test interleaved), payload
  alternates 0 / 12 kg in 15-min blocks, a repeatability burst at the end; optional reference nests on the floor
  measured every ``nest_every`` poses. Timestamps can be withheld from the output.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from robocal.kinematics.frames import make_T, rotvec_to_matrix, skew
from robocal.kinematics.models import Kinematics, chain
from robocal.measure.noise import TrackerUncertainty, repeatability_sigma_mm

G_M_S2 = 9.80665
ARCMIN = np.pi / 180.0 / 60.0
TRUTH_NAMES = ("joint_compliance", "payload_deflection", "gear_cyclic", "backlash", "readback_lag",
               "thermal_drift", "axis_coupling", "registration_drift", "reach_deflection", "joint_jitter",
               "reach_sag_j2")
LIBRARY_TRUTHS = TRUTH_NAMES[:8]           # reach_deflection, joint_jitter and reach_sag_j2: outside the library


def irb2600_nominal() -> Kinematics:
    """Nominal IRB 2600-12/1.65 (DH table of configs/irb2600.yaml), Hayati beta on J2."""
    return Kinematics.from_table("dh", [-90, 0, -90, 90, 90, 0], [150, 700, 115, 0, 0, 0], [445, 0, 0, 795, 0, 85],
                                 [0, -90, 0, 0, 180, 0], [-180, -95, -180, -400, -120, -400],
                                 [180, 155, 75, 400, 120, 400], hayati_joints=[2], p_flange_smr_mm=[0, 0, 100])


@dataclass(frozen=True)
class TruthEffect:
    """One physical effect present in the simulated robot, with its physical values (units in the keys)."""
    name: str
    joints: tuple[int, ...]
    form: str
    values: dict = field(default_factory=dict)


@dataclass(frozen=True)
class CampaignShape:
    """The size and timing of a simulated campaign: calibration/test points, duration (s), payload blocks (kg, s),
    check poses and their repeats, robot repeatability (ISO 9283 RP, mm); the base of ``TruthProtocol``."""
    n_calib: int = 300
    n_test: int = 100
    duration_s: float = 7200.0
    payloads_kg: tuple[float, ...] = (0.0, 12.0)
    payload_block_s: float = 900.0
    check_poses: int = 10
    check_repeats: int = 5
    repeatability_rp_mm: float = 0.04


@dataclass(frozen=True)
class TruthProtocol(CampaignShape):
    timestamps: bool = True
    nest_every: int = 0                   # 0: no reference nests
    nests: int = 3
    q3_fixed_deg: float | None = None     # hold J3 at one angle (data that cannot tell a J2 harmonic from gravity)
    compliance_joints: tuple[int, ...] = (2, 3)
    sampling: str = "uniform"             # uniform | box (small joint ranges in front of a small arm, SMALL_ARM_BOX_DEG)
    #                                       | sparse_extremes (most poses central, a few at the extremes of J2/J3)
    order: str = "random"                 # random | sweep_j1 (measured in order of J1: time correlates with q1)
    misalignment_deg: float = 0.0         # extra parallel-axis misalignment (Hayati beta) of the Hayati joints
    kg_per_mm: float = 0.12               # link mass per mm of link length
    stiffness_nm_per_rad: tuple | None = None   # ((J2 lo, hi), (J3 lo, hi)) instead of the industrial-arm ranges
    gear_joints: tuple[int, ...] = (1, 2, 3, 4, 5, 6)   # joints a gear error is drawn on
    gear_arcsec: float = 20.0             # typical first-harmonic amplitude of a gear error on J1-J3 (x3 on the wrist)
    gravity_base: tuple[float, float, float] = (0.0, 0.0, -1.0)   # gravity in the base frame (floor mount: -z)


@dataclass(frozen=True, eq=False)
class TruthCampaign:
    """Rows in measurement order. ``q_read_rad`` what the controller reports, ``q_cmd_rad`` what was commanded;
    ``p_mm`` tracker frame; ``sets`` calib / test / check. Nest readings: ``nest_p_mm`` (M, 3) tracker frame,
    ``nest_id`` (M,), ``nest_t_s`` (M,), ``nest_after_row`` (M,) index of the last pose measured before them."""
    nominal: Kinematics
    truth_kin: Kinematics
    q_read_rad: np.ndarray
    q_cmd_rad: np.ndarray
    p_mm: np.ndarray
    cov_mm2: np.ndarray
    sets: tuple[str, ...]
    point_id: tuple[str, ...]
    t_s: np.ndarray | None
    payload_kg: np.ndarray
    truths: tuple[TruthEffect, ...]
    nest_p_mm: np.ndarray
    nest_id: tuple[str, ...]
    nest_t_s: np.ndarray | None
    nest_after_row: np.ndarray
    protocol: TruthProtocol

    def mask(self, name: str) -> np.ndarray:
        return np.array([s == name for s in self.sets])


# ============================================================================ physics
def _rng_sign(rng) -> float:
    return float(rng.choice([-1.0, 1.0]))


SMALL_ARM_BOX_DEG = ((-30, -95, 70, -100, 50, -10), (50, -35, 140, 15, 130, 20))   # UR joint conventions
CENTRAL_DEG = ((-10, -25), (25, 5))        # sparse_extremes: (q2, q3) box of the central poses (IRB conventions)


def small_arm_nominal() -> Kinematics:
    """A small 6-axis arm with three parallel axes (the published UR5 DH table), Hayati beta on J2 and J3."""
    return Kinematics.from_table("dh", [90, 0, 0, 90, -90, 0], [0, -425, -392.25, 0, 0, 0],
                                 [89.159, 0, 0, 109.15, 94.65, 82.3], [0] * 6, [-360] * 6, [360] * 6,
                                 hayati_joints=[2, 3], p_flange_smr_mm=[0, 0, 30])


def perturbed_geometry(nominal: Kinematics, rng: np.random.Generator) -> Kinematics:
    """Truth geometry: each DH parameter off by a random amount with a random sign."""
    n = nominal.n
    s = lambda lo, hi: rng.uniform(lo, hi, n) * rng.choice([-1.0, 1.0], n)      # noqa: E731
    beta = np.where(nominal.hayati, np.radians(rng.uniform(-0.015, 0.015, n)), 0.0)
    return nominal.with_(alpha_rad=nominal.alpha_rad + np.radians(s(0.003, 0.03)),
                         a_mm=nominal.a_mm + s(0.05, 0.5), d_mm=nominal.d_mm + s(0.05, 0.5),
                         theta_rad=nominal.theta_rad + np.radians(s(0.005, 0.05)), beta_rad=nominal.beta_rad + beta)


def sample_configurations(kin: Kinematics, rng: np.random.Generator, n: int, q3_fixed_deg: float | None = None,
                          sampling: str = "uniform") -> np.ndarray:
    """n random joint vectors (rad): SMR above the floor and off the base column, wrist off its singularity.
    ``box``: uniform in ``SMALL_ARM_BOX_DEG``; ``sparse_extremes``: 85 % with (q2, q3) in ``CENTRAL_DEG``."""
    if sampling == "box":
        return rng.uniform(np.radians(SMALL_ARM_BOX_DEG[0]), np.radians(SMALL_ARM_BOX_DEG[1]), (n, kin.n))
    lo = np.radians([-120, -50, -120, -180, -115, -180])[:kin.n]
    hi = np.radians([120, 90, 60, 180, 115, 180])[:kin.n]
    out, got = [], 0
    while got < n:
        q = rng.uniform(lo, hi, (4 * n, kin.n))
        if q3_fixed_deg is not None:
            q[:, 2] = np.radians(q3_fixed_deg)
        if sampling == "sparse_extremes":
            central = rng.random(len(q)) < 0.85
            q[central, 1:3] = rng.uniform(np.radians(CENTRAL_DEG[0]), np.radians(CENTRAL_DEG[1]), (central.sum(), 2))
        c = chain(kin, q, full=False)
        p = c.T_base_flange[:, :3, 3]
        ok = (p[:, 2] > 150) & (np.hypot(p[:, 0], p[:, 1]) > 450) & (np.abs(q[:, 4]) > np.radians(15))
        out.append(q[ok])
        got += int(ok.sum())
    return np.concatenate(out)[:n]


@dataclass(frozen=True)
class MassModel:
    """Lumped masses (kg) per link, their centres of mass: ``fraction`` along the link (joint i -> joint i+1,
    last -> flange), ``beside_mm`` perpendicular to the link in the plane normal to the joint axis, ``along_axis_mm``
    along the joint axis; payload centre of mass in the flange frame (mm)."""
    masses_kg: np.ndarray
    fraction: np.ndarray
    beside_mm: np.ndarray
    along_axis_mm: np.ndarray
    payload_com_flange_mm: np.ndarray


def random_mass_model(kin: Kinematics, rng: np.random.Generator, kg_per_mm: float = 0.12) -> MassModel:
    """Link masses of a robot of this size: about ``kg_per_mm`` per mm of link length, x U(0.6, 1.4)."""
    n = kin.n
    length = np.hypot(kin.a_mm, kin.d_mm)
    masses = np.where(np.arange(n) == 0, 0.0, kg_per_mm * np.maximum(length, 80.0) * rng.uniform(0.6, 1.4, n))
    return MassModel(masses, rng.uniform(0.3, 0.7, n), rng.uniform(-60, 60, n), rng.uniform(-30, 30, n),
                     np.array([rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(50, 150)]))


def gravity_torque_nm(kin: Kinematics, q_rad: np.ndarray, mm: MassModel, payload_kg: np.ndarray,
                      arm: bool = True, down=(0.0, 0.0, -1.0)) -> np.ndarray:
    """Gravity torque (N, n) N*m about every joint axis: sum over the downstream centres of mass of
    (r x m g) . axis; gravity along ``down`` in the base frame (-z: floor mount)."""
    c = chain(kin, q_rad, full=False)
    N, n = q_rad.shape
    R_fl = c.T_base_flange[:, :3, :3]
    o = np.concatenate([c.origin, c.T_base_flange[:, None, :3, 3]], axis=1)
    link = o[:, 1:] - o[:, :-1]
    side = np.cross(c.axis, link)
    nrm = np.linalg.norm(side, axis=2, keepdims=True)
    side = np.where(nrm > 1e-6, side / np.maximum(nrm, 1e-9), 0.0)
    com = (o[:, :-1] + mm.fraction[None, :, None] * link + mm.beside_mm[None, :, None] * side
           + mm.along_axis_mm[None, :, None] * c.axis)                                   # (N, n, 3)
    p_pay = c.T_base_flange[:, :3, 3] + np.einsum("nij,j->ni", R_fl, mm.payload_com_flange_mm)
    weights = np.concatenate([np.broadcast_to(mm.masses_kg * (1.0 if arm else 0.0), (N, n)),
                              np.asarray(payload_kg, float).reshape(N, 1)], axis=1) * G_M_S2   # N
    pts = np.concatenate([com, p_pay[:, None, :]], axis=1)                                # (N, n+1, 3)
    tau = np.zeros((N, n))
    force = np.asarray(down, float) / np.linalg.norm(down)
    for j in range(n):
        r = pts[:, j:] - c.origin[:, j:j + 1]                                             # links j.. and payload
        tau[:, j] = np.einsum("nmk,nk,nm->n", np.cross(r, force), c.axis[:, j], weights[:, j:]) / 1000.0
    return tau


def last_moves(q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(move, previous move, sign of the last non-zero move) per row and joint, from rows in motion order."""
    q = np.asarray(q_rad, float)
    move = np.zeros_like(q)
    move[1:] = np.diff(q, axis=0)
    prev = np.zeros_like(q)
    prev[1:] = move[:-1]
    step = np.sign(move)
    last = np.maximum.accumulate(np.where(step != 0.0, np.arange(len(q))[:, None], 0), axis=0)
    sign = step[last, np.arange(q.shape[1])[None, :]]          # the sign persists through zero moves
    return move, prev, sign


def warmup(t_s: np.ndarray, tau_s: float) -> np.ndarray:
    return 1.0 - np.exp(-np.maximum(t_s, 0.0) / tau_s)


# ============================================================================ effects as instances
def draw_effect(name: str, rng: np.random.Generator, kin: Kinematics, scale: float,
                protocol: TruthProtocol = TruthProtocol()) -> TruthEffect:
    """A random physical instance of an effect; ``scale`` multiplies its typical size."""
    u = rng.uniform
    if name == "joint_compliance":
        (a2, b2), (a3, b3) = protocol.stiffness_nm_per_rad or ((1.2e6, 3e6), (0.6e6, 1.5e6))
        k2, k3 = u(a2, b2) / scale, u(a3, b3) / scale
        return TruthEffect(name, (2, 3), "lumped masses, off-line COMs, offset payload (J2 torque depends on q3)",
                           {"stiffness_nm_per_rad": {2: k2, 3: k3}})
    if name == "payload_deflection":
        return TruthEffect(name, (2, 3), "payload torque only (balanced arm)",
                           {"stiffness_nm_per_rad": {2: u(0.6e6, 1.5e6) / scale, 3: u(0.3e6, 0.8e6) / scale}})
    if name == "gear_cyclic":
        joint = int(rng.integers(1, 7)) if len(protocol.gear_joints) == 6 else int(rng.choice(protocol.gear_joints))
        sets = [(1,), (2,), (1, 2), (2, 3), (1, 3)]
        hs = sets[int(rng.integers(len(sets)))]
        base = protocol.gear_arcsec * (1.0 if joint <= 3 else 3.0) / 3600.0 * np.pi / 180.0
        amps = {h: base * scale * u(0.7, 1.3) * (1.0 if h == hs[0] else 0.6) for h in hs}
        return TruthEffect(name, (joint,), f"harmonics {','.join(map(str, hs))}",
                           {"amplitude_rad": amps, "phase_rad": {h: u(-np.pi, np.pi) for h in hs}})
    if name == "backlash":
        joints = sorted(int(j) for j in rng.choice([1, 2, 3], size=int(rng.integers(1, 4)), replace=False))
        return TruthEffect(name, tuple(joints), "constant half-width per approach direction",
                           {"half_width_rad": {j: u(0.5, 1.0) * ARCMIN * scale for j in joints}})
    if name == "readback_lag":
        joints = sorted(int(j) for j in rng.choice([1, 2, 3], size=int(rng.integers(1, 4)), replace=False))
        lag = {j: -5e-4 * u(0.3, 1.0) * scale * (1.0 if rng.random() < 0.8 else -1.0) for j in joints}
        memory = u(0.2, 0.5) if rng.random() < 0.5 else 0.0
        return TruthEffect(name, tuple(joints), "read-back offset proportional to the signed last move"
                           + (f" (memory {memory:.2f} of the move before)" if memory else ""),
                           {"lag_per_move": lag, "memory": memory})
    if name == "thermal_drift":
        dT = u(5.0, 12.0) * scale
        z = {2: u(0.3, 0.8) * ARCMIN * scale * _rng_sign(rng), 3: u(0.3, 0.8) * ARCMIN * scale * _rng_sign(rng)}
        return TruthEffect(name, (2, 3), "exponential warm-up of all link lengths + J2/J3 zero drift",
                           {"alpha_per_k": 1.2e-5 * u(0.8, 1.9), "delta_t_k": dT, "tau_s": u(1200, 3600),
                            "zero_drift_rad": z})
    if name == "axis_coupling":
        e56 = 4e-3 * scale * u(0.8, 1.25) * _rng_sign(rng)
        e45 = u(-2e-3, 2e-3) * scale if rng.random() < 0.5 else 0.0
        return TruthEffect(name, (4, 5, 6) if e45 else (5, 6), "wrist gear coupling", {"e56": e56, "e45": e45})
    if name == "registration_drift":
        d, w = rng.normal(size=3), rng.normal(size=3)
        linear = rng.random() < 0.5
        s = scale * u(0.7, 1.3) * (1.0 if linear else 2.0)
        return TruthEffect(name, (), "linear creep" if linear else "settling stand",
                           {"v_mm": 0.04 * s * d / np.linalg.norm(d), "w_rad": 12e-6 * s * w / np.linalg.norm(w),
                            "linear": linear, "tau_s": u(1200, 3600)})
    if name == "reach_deflection":
        return TruthEffect(name, (), "sag growing with the square of the horizontal reach (not in the library)",
                           {"sag_mm_at_1m": 0.15 * scale * u(0.8, 1.25)})
    if name == "reach_sag_j2":
        return TruthEffect(name, (2,), "J2 turns down by an angle growing with the square of the reach (not in the "
                           "library)", {"sag_rad_at_1m": 8e-5 * scale * u(0.8, 1.25)})
    if name == "joint_jitter":
        return TruthEffect(name, (1, 2, 3), "random noise on the read-back joints (not in the library)",
                           {"sigma_rad": np.radians(0.004) * scale})
    raise ValueError(f"unknown truth effect {name!r}")


# ============================================================================ the campaign
def simulate(effects: Sequence[str], seed: int, protocol: TruthProtocol = TruthProtocol(),
             scale: float | None = None, nominal: Kinematics | None = None, off: Sequence[str] = ()) -> TruthCampaign:
    """One simulated campaign with the named physical effects (``scale`` None: U(0.6, 1.4) per effect).
    ``off``: effects drawn (the same random numbers) but not applied: the same campaign without them, so the
    difference of two calls is what those effects do to the measurements."""
    rng = np.random.default_rng(seed)
    nominal = irb2600_nominal() if nominal is None else nominal
    phi = rng.uniform(-np.pi, np.pi)
    smr = np.array([rng.uniform(50, 80) * np.cos(phi), rng.uniform(50, 80) * np.sin(phi), rng.uniform(80, 120)])
    az, dist = rng.uniform(-np.pi, np.pi), rng.uniform(2500, 4000)
    T_tb = make_T(rotvec_to_matrix(np.array([0, 0, rng.uniform(-np.pi, np.pi)]) + rng.normal(0, 0.01, 3)),
                  np.array([dist * np.cos(az), dist * np.sin(az), rng.uniform(-1200, -600)]))
    truth = perturbed_geometry(nominal, rng).with_(T_tracker_base=T_tb, p_flange_smr_mm=smr)
    pr = protocol
    if pr.misalignment_deg:
        tilt = np.radians(pr.misalignment_deg) * rng.uniform(0.7, 1.3, truth.n) * rng.choice([-1.0, 1.0], truth.n)
        truth = truth.with_(beta_rad=truth.beta_rad + np.where(nominal.hayati, tilt, 0.0))
    nominal = nominal.with_(p_flange_smr_mm=smr + rng.normal(0, 0.5, 3))
    n_main = pr.n_calib + pr.n_test
    q_main = sample_configurations(nominal, rng, n_main, pr.q3_fixed_deg, pr.sampling)
    if pr.order == "sweep_j1":                     # measured in order of J1 (a sweep), not in random order
        q_main = q_main[np.argsort(q_main[:, 0] + np.radians(rng.normal(0.0, 3.0, n_main)))]
    sets = list(np.array(["calib"] * pr.n_calib + ["test"] * pr.n_test)[rng.permutation(n_main)])
    q_chk = sample_configurations(nominal, rng, pr.check_poses, pr.q3_fixed_deg, pr.sampling)
    order = [pr.check_poses - 1] + list(range(pr.check_poses)) * pr.check_repeats
    q_cmd = np.concatenate([q_main, q_chk[order]])
    sets += ["calib"] + ["check"] * (len(order) - 1)
    ids = [f"P{i:04d}" for i in range(n_main)] + ["P-lead"] + [f"CHK{k:02d}" for k in order[1:]]
    N = len(q_cmd)
    dt = pr.duration_s / n_main
    t = np.concatenate([(np.arange(n_main) + rng.uniform(0, 0.5, n_main)) * dt,
                        pr.duration_s + 6.0 * np.arange(1, len(order) + 1)])
    payload = np.asarray(pr.payloads_kg, float)[(t // pr.payload_block_s).astype(int) % len(pr.payloads_kg)]
    payload[n_main:] = pr.payloads_kg[0]
    truths = [draw_effect(name, rng, nominal, float(rng.uniform(0.6, 1.4)) if scale is None else scale, pr)
              for name in effects]
    mass = random_mass_model(nominal, rng, pr.kg_per_mm)
    move, prev, sign = last_moves(q_cmd)
    # ---- link angles (where the robot really is) and what the controller reports
    q_link = q_cmd.copy()
    q_read = q_cmd + rng.normal(0.0, np.radians(2e-4), q_cmd.shape)             # encoder resolution
    a_mm, d_mm = np.broadcast_to(truth.a_mm, (N, truth.n)).copy(), np.broadcast_to(truth.d_mm, (N, truth.n)).copy()
    theta = np.broadcast_to(truth.theta_rad, (N, truth.n)).copy()
    dp_tracker = np.zeros((N, 3))
    sag_mm_per_m2 = 0.0
    for te in truths:
        v = te.values
        if te.name == "joint_jitter":                 # drawn whether applied or not: the same campaign otherwise
            jitter = rng.normal(0.0, v["sigma_rad"], (N, len(te.joints)))
            if te.name not in off:
                q_read[:, np.array(te.joints) - 1] += jitter
        if te.name in off:
            continue
        if te.name in ("joint_compliance", "payload_deflection"):
            tau = gravity_torque_nm(truth, q_cmd, mass, payload, te.name == "joint_compliance", pr.gravity_base)
            for j, k in v["stiffness_nm_per_rad"].items():
                if j in pr.compliance_joints:
                    q_link[:, j - 1] += tau[:, j - 1] / k
        elif te.name == "gear_cyclic":
            j = te.joints[0] - 1
            for h, A in v["amplitude_rad"].items():
                q_link[:, j] += A * np.sin(h * q_cmd[:, j] + v["phase_rad"][h])
        elif te.name == "backlash":
            for j, b in v["half_width_rad"].items():
                q_link[:, j - 1] -= b * sign[:, j - 1]
        elif te.name == "readback_lag":
            for j, lam in v["lag_per_move"].items():
                q_read[:, j - 1] += lam * (move[:, j - 1] + v["memory"] * prev[:, j - 1])
        elif te.name == "axis_coupling":
            q_link[:, 5] += v["e56"] * q_cmd[:, 4]
            q_link[:, 4] += v["e45"] * q_cmd[:, 3]
        elif te.name == "thermal_drift":
            g = v["alpha_per_k"] * v["delta_t_k"] * warmup(t, v["tau_s"])
            a_mm *= (1.0 + g)[:, None]
            d_mm *= (1.0 + g)[:, None]
            for j, z in v["zero_drift_rad"].items():
                theta[:, j - 1] += z * warmup(t, v["tau_s"])
        elif te.name == "registration_drift":
            s = t / 3600.0 if v["linear"] else warmup(t, v["tau_s"])
            p0 = _smr_tracker(truth, q_cmd, a_mm, d_mm, theta)
            dp_tracker += s[:, None] * (v["v_mm"] + np.cross(v["w_rad"], p0 - T_tb[:3, 3]))
        elif te.name == "reach_deflection":
            sag_mm_per_m2 = v["sag_mm_at_1m"]
        elif te.name == "reach_sag_j2":
            q_link[:, 1] += _j2_sag(truth, q_cmd, v["sag_rad_at_1m"])
    p_true = _smr_tracker(truth, q_link, a_mm, d_mm, theta)
    if sag_mm_per_m2:
        c = chain(truth, q_link, full=False)
        p_base = c.T_base_flange[:, :3, 3] + np.einsum("nij,j->ni", c.T_base_flange[:, :3, :3], smr)
        sag = -sag_mm_per_m2 * (np.hypot(p_base[:, 0], p_base[:, 1]) / 1000.0) ** 2
        p_true = p_true + sag[:, None] * T_tb[:3, 2][None, :]
    p_true = p_true + dp_tracker
    tracker = TrackerUncertainty()
    s_rep = repeatability_sigma_mm(pr.repeatability_rp_mm)
    p_rep = p_true + rng.normal(0.0, s_rep, p_true.shape)
    cov = tracker.covariance(p_rep)
    p_meas = p_rep + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((N, 3)))
    cov = cov + s_rep**2 * np.eye(3)
    # ---- reference nests on the floor, measured every nest_every poses (same drift of the tracker stand)
    nest_p, nest_id, nest_t, nest_after = _nests(pr, rng, truth, [te for te in truths if te.name not in off], t, N)
    return TruthCampaign(nominal, truth, q_read, q_cmd, p_meas, cov, tuple(sets), tuple(ids),
                         t if pr.timestamps else None, payload, tuple(truths), nest_p, nest_id,
                         nest_t if pr.timestamps else None, nest_after, pr)


def _j2_sag(kin: Kinematics, q: np.ndarray, rad_at_1m: float) -> np.ndarray:
    """J2 angle (N,) rad that lowers the flange by rad_at_1m x (horizontal reach / 1 m)^2 radians."""
    p = chain(kin, q, full=False).T_base_flange[:, :3, 3]
    dq = np.zeros_like(q)
    dq[:, 1] = 1e-6
    dz = chain(kin, q + dq, full=False).T_base_flange[:, 2, 3] - p[:, 2]
    return -rad_at_1m * (np.hypot(p[:, 0], p[:, 1]) / 1000.0) ** 2 * np.sign(dz)


def _smr_tracker(kin: Kinematics, q, a_mm, d_mm, theta) -> np.ndarray:
    c = chain(kin, q, a=a_mm, d=d_mm, theta=theta, full=False)
    p_base = c.T_base_flange[:, :3, 3] + np.einsum("nij,j->ni", c.T_base_flange[:, :3, :3], kin.p_flange_smr_mm)
    return p_base @ kin.T_tracker_base[:3, :3].T + kin.T_tracker_base[:3, 3]


def _nests(pr: TruthProtocol, rng, truth: Kinematics, truths, t, N):
    if pr.nest_every <= 0:
        return np.zeros((0, 3)), (), np.zeros(0), np.zeros(0, int)
    ang = rng.uniform(-np.pi, np.pi) + np.linspace(0, 2 * np.pi, pr.nests, endpoint=False)
    nests_base = np.stack([1300 * np.cos(ang), 1300 * np.sin(ang), np.zeros(pr.nests)], axis=1)
    after = np.arange(0, N, pr.nest_every)
    after = np.unique(np.concatenate([[0], after, [N - 1]]))
    rows = np.repeat(after, pr.nests)
    which = np.tile(np.arange(pr.nests), len(after))
    tt = t[rows] + 2.0 + 3.0 * which
    p = nests_base[which] @ truth.T_tracker_base[:3, :3].T + truth.T_tracker_base[:3, 3]
    for te in truths:
        if te.name == "registration_drift":
            v = te.values
            s = tt / 3600.0 if v["linear"] else warmup(tt, v["tau_s"])
            p = p + s[:, None] * (v["v_mm"] + np.cross(v["w_rad"], p - truth.T_tracker_base[:3, 3]))
    cov = TrackerUncertainty().covariance(p)
    p = p + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal(p.shape))
    return p, tuple(f"N{k + 1}" for k in which), tt, rows
