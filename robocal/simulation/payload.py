"""Heavy-payload scenario of seed 003 §4: an IRB 4600-60/2.05 whose structure deflects with the payload.

Truth = nominal DH (seed 003) + seeded geometric errors + two deflections that grow with the payload:

* joint deflection: ``dq_j = c_j tau_j(q, payload)`` from the gravity torques of lumped link masses and the
  payload at its centre of gravity (``effects.gravity_torques``);
* link bending: the upper arm (joint 2 -> joint 3) and the forearm (joint 3 -> wrist centre) are end-loaded
  Euler-Bernoulli cantilevers carrying everything downstream. The component of that weight across the link
  bends its end by ``delta = F L^3 / (3 EI)`` and turns it by ``1.5 delta / L``: to first order a rigid
  rotation of the downstream chain by ``1.5 delta / L`` about the point one third along the link.

Measurement: robot repeatability as a rigid per-pose perturbation of the flange (translation sigma_rep per
axis, rotation sigma_rep / 1000 mm rad per axis) shared by every SMR on the tool, plus per-point tracker noise
from the spherical model. Lengths mm, angles rad, masses kg.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.kinematics.gravity import G_MM_S2, gravity_torques
from robocal.kinematics.frames import make_T, rotvec_to_matrix, transform_points
from robocal.kinematics.models import Kinematics, chain
from robocal.measure.noise import TrackerUncertainty, repeatability_sigma_mm

# seed 003 §4 / IRB 4600-60/2.05: nominal DH (deg, mm) and axis ranges (deg)
IRB4600_DH = {"alpha_deg": [-90, 0, -90, 90, 90, 0], "a_mm": [175, 900, 175, 0, 0, 0],
              "d_mm": [495, 0, 0, 960, 0, 135], "theta_deg": [0, -90, 0, 0, 180, 0]}
IRB4600_LIMITS_DEG = ([-180, -90, -180, -400, -125, -400], [180, 150, 75, 400, 125, 400])
SEED003_PAYLOADS_KG = (5.25, 12.10, 41.15, 46.05)
# configs/irb4600.yaml: base -> tracker, tracker ~3.9 m from the work zone, yawed ~155 deg
T_TRACKER_BASE_IRB4600 = np.array([[-0.906195978, -0.422446017, -0.018660451, 4567.499],
                                   [0.422566124, -0.906327607, -0.002852824, -2556.166],
                                   [-0.015707317, -0.010470492, 0.999821809, -1222.278],
                                   [0.0, 0.0, 0.0, 1.0]])


def irb4600(p_flange_smr_mm=(0.0, 0.0, 39.4), T_tracker_base=None) -> Kinematics:
    """Nominal IRB 4600-60/2.05 (standard DH, joints 2 and 3 parallel: Hayati beta on joint 2)."""
    T = T_TRACKER_BASE_IRB4600.copy() if T_tracker_base is None else T_tracker_base
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T = T.copy()
    T[:3, :3] = U @ Vt
    return Kinematics.from_table("dh", IRB4600_DH["alpha_deg"], IRB4600_DH["a_mm"], IRB4600_DH["d_mm"],
                                 IRB4600_DH["theta_deg"], *IRB4600_LIMITS_DEG, hayati_joints=[2],
                                 T_tracker_base=T, p_flange_smr_mm=p_flange_smr_mm)


@dataclass(frozen=True)
class DeflectionModel:
    """Payload-dependent deflection. ``compliance_rad_per_Nm`` (n,) joint compliances; ``link_masses_kg``
    (n,) lumped at the link midpoints; ``EI_upper_Nmm2`` / ``EI_fore_Nmm2`` bending stiffness of the upper arm
    and forearm; ``payload_cog_flange_mm`` payload centre of gravity in the flange frame."""
    compliance_rad_per_Nm: tuple = (0.0, 4.0e-7, 6.0e-7, 1.5e-6, 1.5e-6, 0.0)
    link_masses_kg: tuple = (0.0, 70.0, 55.0, 30.0, 8.0, 2.0)
    EI_upper_Nmm2: float = 2.0e12
    EI_fore_Nmm2: float = 1.2e12
    payload_cog_flange_mm: tuple = (0.0, 0.0, 150.0)


def _bend(T: np.ndarray, root: np.ndarray, tip: np.ndarray, load_N: np.ndarray, EI: float) -> np.ndarray:
    """Left-apply the cantilever rotation of one link to downstream poses T (N, 4, 4)."""
    l_vec = tip - root
    L = np.linalg.norm(l_vec, axis=1)
    u = l_vec / L[:, None]
    f_perp = load_N - np.einsum("ni,ni->n", load_N, u)[:, None] * u
    delta = np.linalg.norm(f_perp, axis=1) * L**3 / (3.0 * EI)                 # mm
    n = np.cross(u, f_perp)
    n_norm = np.linalg.norm(n, axis=1)
    omega = (1.5 * delta / L / np.where(n_norm > 0, n_norm, 1.0))[:, None] * n  # rad, about n
    R = rotvec_to_matrix(omega)
    c = root + L[:, None] / 3.0 * u
    M = make_T(R, c - np.einsum("nij,nj->ni", R, c))
    return M @ T


def deflected_flange(kin: Kinematics, q_rad: np.ndarray, payload_kg, model: DeflectionModel = DeflectionModel()
                     ) -> np.ndarray:
    """True T_base_flange (N, 4, 4) of a robot with geometry ``kin`` carrying ``payload_kg`` (scalar or (N,))."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    pay = np.broadcast_to(np.asarray(payload_kg, float), (len(q),))
    masses = np.asarray(model.link_masses_kg, float)
    kin_cog = kin.with_(p_flange_smr_mm=np.asarray(model.payload_cog_flange_mm, float))
    tau = gravity_torques(kin_cog, q, masses, pay)                                # N m
    c = chain(kin, q + tau * np.asarray(model.compliance_rad_per_Nm, float), full=False)
    T = c.T_base_flange
    g = np.array([0.0, 0.0, -G_MM_S2])                                          # N per kg
    wrist = c.origin[:, 4]                                                      # wrist centre (axes 4, 5, 6)
    T = _bend(T, c.origin[:, 2], wrist, (pay + masses[3:].sum())[:, None] * g, model.EI_fore_Nmm2)
    return _bend(T, c.origin[:, 1], c.origin[:, 2], (pay + masses[2:].sum())[:, None] * g, model.EI_upper_Nmm2)


@dataclass(frozen=True, eq=False)
class HeavyPayloadCell:
    """Simulated heavy-payload cell: ``truth`` (geometry + T_tracker_base), deflection model, tracker noise and
    robot repeatability (ISO 9283 RP, mm)."""
    truth: Kinematics
    deflection: DeflectionModel = DeflectionModel()
    tracker: TrackerUncertainty = TrackerUncertainty()
    repeatability_rp_mm: float = 0.06

    def true_points(self, q_rad: np.ndarray, payload_kg, p_flange_mm: np.ndarray) -> np.ndarray:
        """Noise-free positions (N, K, 3) mm in the tracker frame of flange-fixed points p_flange_mm (K, 3)."""
        T = self.truth.T_tracker_base @ deflected_flange(self.truth, q_rad, payload_kg, self.deflection)
        return transform_points(T[:, None], np.atleast_2d(p_flange_mm)[None])

    def measure(self, q_rad: np.ndarray, payload_kg, p_flange_mm: np.ndarray, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray]:
        """Measured positions (N, K, 3) mm of the points (one robot stop per pose, every point measured there)
        and their actual positions at that stop (repeatability included, tracker noise not): the truth a pose
        estimate should find. ``true_points`` gives the deterministic, repeatable positions."""
        q = np.atleast_2d(q_rad)
        T = self.truth.T_tracker_base @ deflected_flange(self.truth, q, payload_kg, self.deflection)
        s = repeatability_sigma_mm(self.repeatability_rp_mm)
        T_rep = make_T(rotvec_to_matrix(rng.normal(0.0, s / 1000.0, (len(q), 3))), rng.normal(0.0, s, (len(q), 3)))
        pts = np.atleast_2d(p_flange_mm)[None]
        real = transform_points((T @ T_rep)[:, None], pts)
        cov = self.tracker.covariance(real.reshape(-1, 3))
        noise = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((len(cov), 3)))
        return real + noise.reshape(real.shape), real


def random_configurations(n: int = 181, seed: int = 0) -> np.ndarray:
    """n joint configurations (rad) uniform in a measurement zone in front of the robot (deg):
    q1 [-40, 40], q2 [-20, 50], q3 [-50, 20], q4 [-60, 60], q5 [-90, -20], q6 [-90, 90]."""
    lo = np.radians([-40, -20, -50, -60, -90, -90])
    hi = np.radians([40, 50, 20, 60, -20, 90])
    return np.random.default_rng(seed).uniform(lo, hi, (n, 6))
