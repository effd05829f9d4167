"""The one gravity-torque model of the calibration (``robocal.effects`` re-exports it): lumped link masses, the
payload at its centre of gravity, gravity in any direction; default masses for any joint count."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .frames import transform_points
from .models import CHAIN_ROWS, Kinematics, chain

G_MM_S2 = 9.80665


# ---------------------------------------------------------------- gravity torques: the one torque model
def gravity_torques(kin: Kinematics, q_rad: np.ndarray, link_masses_kg, payload_kg, payload_cog_flange_mm=None,
                    gravity_base=(0.0, 0.0, -1.0)) -> np.ndarray:
    """Gravity torque about each joint axis (N, n) in N·m from lumped masses at the midpoint of each
    link (joint origin i -> joint origin i+1, the last one -> flange) and a payload at its centre of gravity
    ``payload_cog_flange_mm`` in the flange frame (None: at the SMR). ``gravity_base``: direction of gravity in
    the base frame (floor mount -z; a wall or ceiling mount another unit vector)."""
    q = np.atleast_2d(q_rad)
    N, n = q.shape
    pay = np.broadcast_to(np.asarray(payload_kg, float), (N,))
    masses = np.broadcast_to(np.asarray(link_masses_kg, float), (N, n))
    if N > CHAIN_ROWS:                   # row blocks: the frames and the torques of one block in cache
        tau = np.empty((N, n))
        for s in range(0, N, CHAIN_ROWS):
            b = slice(s, s + CHAIN_ROWS)
            tau[b] = gravity_torques(kin, q[b], masses[b], pay[b], payload_cog_flange_mm, gravity_base)
        return tau
    c = chain(kin, q, full=False)
    o_next = np.concatenate([c.origin[:, 1:], c.T_base_flange[:, None, :3, 3]], axis=1)    # (N, n, 3)
    cog = kin.p_flange_smr_mm if payload_cog_flange_mm is None else np.asarray(payload_cog_flange_mm, float)
    p_pay = transform_points(c.T_base_flange, cog)
    g = np.asarray(gravity_base, float)
    force = G_MM_S2 * g / np.linalg.norm(g)                                      # per kg, N
    # everything hanging on joint j (links j..n-1 at their midpoints, the payload): its mass M_j and first moment
    # S_j (kg mm); tau_j = ((S_j - M_j o_j) x F) . axis_j = (S_j - M_j o_j) . (F x axis_j)
    moment = masses[:, :, None] * (0.5 * (c.origin + o_next))
    S = np.cumsum(moment[:, ::-1], axis=1)[:, ::-1] + (pay[:, None] * p_pay)[:, None, :]
    M = np.cumsum(masses[:, ::-1], axis=1)[:, ::-1] + pay[:, None]
    arm = S - M[:, :, None] * c.origin                                           # (N, n, 3) kg mm
    tau = np.einsum("njk,njk->nj", arm, np.cross(force, c.axis)) / 1000.0       # N·mm -> N·m
    tau[:, :kin.n_track] = 0.0                                                   # a track carries, it turns nothing
    return tau


def lever_torques(kin: Kinematics, q_rad: np.ndarray, joints, gravity_base=(0.0, 0.0, -1.0)
                  ) -> dict[int, tuple[np.ndarray, tuple[str, ...]]]:
    """{joint: (torque per kg (N, m) N·m/kg, point names)} about each of ``joints`` (1-based) of a mass at every
    downstream joint origin, the flange and a point beside the next link: any lumped mass fixed on those links
    loads the joint by a combination of them (the mass distribution of ``joint_compliance(form="levers")``)."""
    q = np.atleast_2d(q_rad)
    c = chain(kin, q, full=False)
    flange = c.T_base_flange[:, :3, 3]
    g = np.asarray(gravity_base, float)
    force = G_MM_S2 * g / np.linalg.norm(g)
    out = {}
    for joint in joints:
        j = joint - 1
        nxt = c.origin[:, j + 1] if j + 1 < kin.n else flange
        pts = [(f"o{i + 1}", c.origin[:, i]) for i in range(j + 1, kin.n)] + [("flange", flange)]
        pts.append(("beside", c.origin[:, j] + np.cross(c.axis[:, j], nxt - c.origin[:, j])))
        P = np.stack([pt for _, pt in pts], axis=1) - c.origin[:, j:j + 1]               # (N, m, 3)
        tau = np.einsum("nmk,nk->nm", np.cross(P, force), c.axis[:, j]) / 1000.0
        out[joint] = (tau, tuple(name for name, _ in pts))
    return out


def link_frames(kin: Kinematics, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A frame fixed to each moving link: (origins (N, n, 3) mm, axes (N, n, 3, 3) with columns e1 e2 e3), base
    frame. Link i (0-based, turned by joint i) has its origin on joint i's axis, e1 along that axis and e2 the part
    of the next link's axis or of the link vector (the longer one) across e1; the last link takes the flange's x or y.
    Every one is fixed to its link (a point on a link's own axis and the next joint's axis and origin move with it)."""
    q = np.atleast_2d(q_rad)
    c = chain(kin, q, full=False)
    pick = _e2_pick(kin)
    axes = np.empty(q.shape + (3, 3))
    for i, (e1, across) in enumerate(zip(*_across(c))):
        e2 = across[pick[i]] / np.maximum(np.linalg.norm(across[pick[i]], axis=1, keepdims=True), 1e-12)
        axes[:, i] = np.stack([e1, e2, np.cross(e1, e2)], axis=2)
    return c.origin, axes


def _across(c) -> tuple[list, list]:
    """Per link: its unit axis e1 (N, 3) and the two candidates for e2 (``link_frames``) across it (N, 3) each."""
    n = c.axis.shape[1]
    flange = c.T_base_flange[:, :3, :3]
    o_next = np.concatenate([c.origin[:, 1:], c.T_base_flange[:, None, :3, 3]], axis=1)
    e1s, acr = [], []
    for i in range(n):
        e1 = c.axis[:, i] / np.linalg.norm(c.axis[:, i], axis=1, keepdims=True)
        cands = [c.axis[:, i + 1], o_next[:, i] - c.origin[:, i]] if i + 1 < n else [flange[:, :, 0], flange[:, :, 1]]
        e1s.append(e1)
        acr.append([v - np.sum(v * e1, axis=1, keepdims=True) * e1 for v in cands])
    return e1s, acr


def _e2_pick(kin: Kinematics) -> list[int]:
    """Per link, which e2 candidate ``link_frames`` takes: the longer across e1 in the zero pose, the first on a tie.
    Both are fixed to the link, so their lengths are those of every pose: one pick for every call."""
    _, across = _across(chain(kin, np.zeros((1, kin.n)), full=False))
    return [int(np.linalg.norm(a[1][0]) > np.linalg.norm(a[0][0]) * (1.0 + 1e-6)) for a in across]


LINK_OFFSET_MM = 100.0    # the offset columns of ``link_mass_torques``: per kg displaced by 100 mm


def link_mass_torques(kin: Kinematics, q_rad: np.ndarray, joints, gravity_base=(0.0, 0.0, -1.0)
                      ) -> dict[int, tuple[np.ndarray, tuple[str, ...]]]:
    """{joint: (torque per kg (N, m) N·m/kg, column names)} about each of ``joints`` (1-based) of the complete
    gravity regressor of the links it carries: per link i from the joint's own, a kg at the link frame's origin
    (``o``) and a kg displaced by ``LINK_OFFSET_MM`` along each of its axes (``x y z``; ``link_frames``). Any mass
    rigidly fixed on those links, wherever its centre, loads the joint by a combination of them (the mass
    distribution of ``joint_compliance(form="links")``); the joint's own link contributes its two across-axis
    columns only (its origin and axis give no torque about itself)."""
    q = np.atleast_2d(q_rad)
    origin, axes = link_frames(kin, q)
    g = np.asarray(gravity_base, float)
    force = G_MM_S2 * g / np.linalg.norm(g)
    out = {}
    for joint in joints:
        j = joint - 1
        lever = np.cross(force, axes[:, j, :, 0])               # tau = (p - o_j) . (F x a_j) / 1000 for a kg at p
        to = np.einsum("nik,nk->ni", origin[:, j:] - origin[:, j:j + 1], lever) / 1000.0
        ta = np.einsum("nikm,nk->nim", axes[:, j:], lever) * (LINK_OFFSET_MM / 1000.0)
        cols = np.concatenate([to[:, :, None], ta], axis=2).reshape(len(q), -1)[:, 2:]    # own link: y, z only
        names = tuple(f"L{i + 1}{s}" for i in range(j, kin.n) for s in "oxyz")[2:]
        out[joint] = (cols, names)
    return out


DEFAULT_LINK_MASSES_KG = (0.0, 35.0, 40.0, 12.0, 4.0, 1.0)
MOVING_SHARE = 0.7      # the moving links carry ~70 % of a 6-axis arm's datasheet mass (base and J1 column the rest)


def default_link_masses(n: int) -> tuple[float, ...]:
    """Default lumped link masses (kg) of an n-joint arm: ``DEFAULT_LINK_MASSES_KG`` for six joints; for another
    count the same mass distribution along the chain (its cumulative share at each link's end, resampled from
    six links to n by chain position): heavy upper and lower arm, light wrist, the same total."""
    if n == len(DEFAULT_LINK_MASSES_KG):
        return DEFAULT_LINK_MASSES_KG
    cum = np.concatenate([[0.0], np.cumsum(DEFAULT_LINK_MASSES_KG)])
    at = np.interp(np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, len(cum)), cum)
    return tuple(float(m) for m in np.diff(at))


@dataclass(frozen=True)
class GravityModel:
    """The one gravity-torque model of the calibration: lumped link masses (kg, one per joint's link), the
    payload's centre of gravity in the flange frame (mm) and the direction of gravity in the base frame.
    ``source``: "config" (``robot.link_masses_kg``), "mass class" (``robot.mass_kg`` x ``MOVING_SHARE`` shared
    over the links as ``DEFAULT_LINK_MASSES_KG``) or "default" (``DEFAULT_LINK_MASSES_KG``, a ~130 kg arm: the
    shape of the torques is right for a typical 6-axis arm, stiffnesses scale with the true moving mass)."""
    link_masses_kg: tuple[float, ...] = DEFAULT_LINK_MASSES_KG
    payload_cog_flange_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gravity_base: tuple[float, float, float] = (0.0, 0.0, -1.0)
    source: str = "default"

    @classmethod
    def of_robot(cls, n: int, link_masses_kg=None, mass_kg: float | None = None,
                 payload_cog_flange_mm=(0.0, 0.0, 0.0), gravity_base=(0.0, 0.0, -1.0)) -> "GravityModel":
        """From the config: explicit link masses, else the size law of the robot's mass class, else the default."""
        shares = np.asarray(default_link_masses(n), float)
        if link_masses_kg is not None:
            masses, source = link_masses(n, link_masses_kg), "config"
        elif mass_kg is not None:
            masses, source = MOVING_SHARE * float(mass_kg) * shares / max(shares.sum(), 1e-12), "mass class"
        else:
            masses, source = shares, "default"
        g = np.asarray(gravity_base, float)
        return cls(tuple(float(m) for m in masses), tuple(float(v) for v in payload_cog_flange_mm),
                   tuple(float(v) for v in g / np.linalg.norm(g)), source)

    def sized(self, n: int) -> "GravityModel":
        """This model for an n-joint chain: the default masses resampled to n links (``default_link_masses``);
        configured masses already have one per joint."""
        if self.source != "default" or len(self.link_masses_kg) == n:
            return self
        return replace(self, link_masses_kg=default_link_masses(n))

    def options(self) -> tuple[tuple[str, object], ...]:
        """Keyword options of the elastic effect factories (stored with a fitted effect in model.json)."""
        return (("link_masses_kg", self.link_masses_kg), ("payload_cog_flange_mm", self.payload_cog_flange_mm),
                ("gravity_base", self.gravity_base))


def link_masses(n: int, masses) -> np.ndarray:
    """(n,) masses (kg): the given ones, cut or padded with zeros to n links."""
    m = np.zeros(n)
    src = np.asarray(masses, float)
    m[: min(n, len(src))] = src[: min(n, len(src))]
    return m


# ---------------------------------------------------------------- effect factories
