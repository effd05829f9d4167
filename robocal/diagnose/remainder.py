"""What is left after the final model: structure (something predicts it on held-out points), excess noise
(nothing does) or none (at the floor), with the evidence and the likely source of a noise excess.

Evidence:

* **prediction**: the share of the excess over the floor that the best non-parametric layer (GPR over the
  joints, or the joint-error GP) removes on held-out points, with the paired t of that gain; and the
  neighbour test's structured variance (``regions.structure_test``: S in floor units, about 3 U^2 / F^2);
* **nugget**: the noise variance of the remainder, from its variogram over neighbouring poses in joint space
  (half the mean squared difference of neighbours, extrapolated to zero distance): what repeats at the same
  pose would scatter by;
* **repeat spread**: the floor itself when it comes from repeated poses;
* **shape of the noise**: the outer products r r^T of the remainder fitted (non-negative least squares) as
  a x the declared covariance + sum_j s_j^2 J_j J_j^T: noise that moves the SMR along the joints' directions
  is noise of the joint readings, noise shaped like the declared one is the tracker or the robot's
  repeatability (then the floor is under-declared);
* **read-back jitter**: with commanded joints, the scatter of read-back minus commanded once a lag on the move
  is removed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import cKDTree

from robocal.effects.cv import spread_scaled

from .jsonable import json_float, plain

KINDS = ("structure", "noise", "none")


@dataclass(frozen=True)
class Remainder:
    """``kind`` in KINDS; ``rms_mm`` the held-out RMS above the floor (sqrt(R^2 - F^2)); ``heldout_rms_mm`` R and
    ``floor_mm`` F; ``source`` the likely source of a noise excess (None otherwise); ``evidence`` the figures."""
    kind: str
    rms_mm: float
    heldout_rms_mm: float
    floor_mm: float
    source: str | None
    text: str
    evidence: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "rms_mm": json_float(self.rms_mm), "heldout_rms_mm": json_float(self.heldout_rms_mm),
                "floor_mm": json_float(self.floor_mm), "source": self.source, "text": self.text,
                "evidence": plain(self.evidence)}

    @classmethod
    def from_dict(cls, d: Mapping) -> "Remainder":
        f = lambda k: float("nan") if d.get(k) is None else float(d[k])  # noqa: E731
        return cls(str(d["kind"]), f("rms_mm"), f("heldout_rms_mm"), f("floor_mm"), d.get("source"),
                   str(d.get("text", "")), dict(d.get("evidence") or {}))


def nugget(r_mm: np.ndarray, q_rad: np.ndarray, k: int = 6, dof_share: float = 0.0) -> dict:
    """Variogram of residuals r (N, 3) mm over neighbouring poses (joints scaled by their spread): per pair of
    k nearest neighbours gamma = |r_i - r_j|^2 / 2 (3-D); the nugget is the intercept of gamma against the
    neighbour distance (least squares, clipped to [0, sill]); ``dof_share``: share of the residual's degrees of
    freedom used by the fit (in-sample residuals are inflated by 1 / (1 - dof_share)). mm^2."""
    q = np.asarray(q_rad, float)
    x = spread_scaled(q)
    x = x if x.shape[1] else np.zeros((len(q), 1))
    k = min(k, len(q) - 1)
    inflate = 1.0 / max(1.0 - dof_share, 0.5)
    sill = float(np.mean(np.sum((r_mm - r_mm.mean(axis=0)) ** 2, axis=1))) * inflate
    if k < 2:
        return {"nugget_mm2": sill, "sill_mm2": sill, "nearest_mm2": sill}
    d, nn = cKDTree(x).query(x, k=k + 1)
    d, nn = d[:, 1:].ravel(), nn[:, 1:].ravel()
    i = np.repeat(np.arange(len(q)), k)
    g = 0.5 * np.sum((r_mm[i] - r_mm[nn]) ** 2, axis=1) * inflate
    A = np.stack([np.ones_like(d), d], axis=1)
    a, b = np.linalg.lstsq(A, g, rcond=None)[0]
    return {"nugget_mm2": float(np.clip(a if b >= 0 else g.mean(), 0.0, sill)), "sill_mm2": sill,
            "nearest_mm2": float(g[::k].mean()) if k else sill, "slope_mm2_per_sd": float(b)}


def noise_shape(r_mm: np.ndarray, cov_mm2: np.ndarray, J_joint: np.ndarray) -> dict:
    """r r^T of residuals r (N, 3) fitted as a * cov (N, 3, 3: the declared covariance, scaled to the floor) +
    sum_j s_j^2 J_j J_j^T (J_joint (N, 3, n) mm/rad) by non-negative least squares over the six distinct
    elements: {"declared_scale": a, "joint_sigma_rad": (n,), "joint_mm2": per-joint share of the mean squared
    residual, "declared_mm2"}."""
    iu = np.triu_indices(3)
    w = np.where(iu[0] == iu[1], 1.0, math.sqrt(2.0))          # off-diagonals count twice in a Frobenius norm
    y = (r_mm[:, :, None] * r_mm[:, None, :])[:, iu[0], iu[1]] * w
    cols = [cov_mm2[:, iu[0], iu[1]] * w]
    for j in range(J_joint.shape[2]):
        Jj = J_joint[:, :, j]
        cols.append((Jj[:, :, None] * Jj[:, None, :])[:, iu[0], iu[1]] * w)
    A = np.stack([c.ravel() for c in cols], axis=1)
    nrm = np.linalg.norm(A, axis=0)
    nrm[nrm == 0] = 1.0
    x = nnls(A / nrm, y.ravel())[0] / nrm
    joint_mm2 = x[1:] * np.mean(np.sum(J_joint**2, axis=1), axis=0)
    return {"declared_scale": float(x[0]), "joint_sigma_rad": np.sqrt(x[1:]),
            "joint_mm2": joint_mm2, "declared_mm2": float(x[0] * np.mean(np.trace(cov_mm2, axis1=1, axis2=2)))}


def readback_jitter(q_read_rad: np.ndarray, q_cmd_rad: np.ndarray, move_rad: np.ndarray | None,
                    prev_rad: np.ndarray | None) -> np.ndarray:
    """Per-joint RMS (n,) rad of read-back minus commanded after a lag on the last move and the move before
    (least squares per joint) is removed."""
    d = np.asarray(q_read_rad, float) - np.asarray(q_cmd_rad, float)
    out = np.empty(d.shape[1])
    for j in range(d.shape[1]):
        X = [np.ones(len(d))] + [m[:, j] for m in (move_rad, prev_rad) if m is not None]
        X = np.stack(X, axis=1)
        e = d[:, j] - X @ np.linalg.lstsq(X, d[:, j], rcond=None)[0]
        out[j] = math.sqrt(float(np.mean(e**2)))
    return out


STRUCTURE_SHARE = 0.25     # a predictor that removes this share of the excess on held-out points: structure
PREDICT_T = 2.0            # ... with a paired t of its per-point gain at least this
JOINT_SHARE = 0.5          # noise whose joint-shaped part is this share of the noise excess: the joint readings


@dataclass(frozen=True, eq=False)
class RemainderEvidence:
    """What the classification reads: held-out RMS R and floor F (mm), whether R is above the floor
    (``flagged``), the best layer's name, held-out RMS and paired t, the neighbour test's largest structured
    variance (mm^2) and the input it lies along, the nugget (``nugget``), the shape of the noise
    (``noise_shape``), the read-back jitter per joint (rad, or None) with the joints' mean lever (mm/rad),
    the floor's source."""
    R: float
    F: float
    flagged: bool
    layer: str
    layer_rms: float
    layer_t: float
    neighbour_mm2: float
    neighbour_along: str | None
    nugget: dict
    shape: dict
    jitter_rad: np.ndarray | None
    lever_mm: np.ndarray
    floor_source: str


def classify(ev: RemainderEvidence) -> Remainder:
    """The remainder's kind, likely source and sentence from its evidence."""
    R, F = ev.R, ev.F
    excess2 = max(R**2 - F**2, 0.0)
    pred_share = max(R**2 - ev.layer_rms**2, 0.0) / excess2 if excess2 > 0 else 0.0
    neigh_share = ev.neighbour_mm2 / excess2 if excess2 > 0 else 0.0
    noise2 = ev.nugget["nugget_mm2"]
    out = {"predicted_share": pred_share, "predictor": ev.layer, "predictor_heldout_rms_mm": ev.layer_rms,
           "predictor_t": ev.layer_t, "neighbour_structure_mm": math.sqrt(max(ev.neighbour_mm2, 0.0)),
           "neighbour_share": neigh_share, "neighbour_along": ev.neighbour_along,
           "nugget_mm": math.sqrt(noise2), "sill_mm": math.sqrt(ev.nugget["sill_mm2"]),
           "repeat_spread_mm": F if ev.floor_source == "repeats" else None, "floor_source": ev.floor_source}
    joint2 = np.asarray(ev.shape["joint_mm2"], float)
    out["joint_noise_deg"] = {f"J{j + 1}": math.degrees(s) for j, s in enumerate(ev.shape["joint_sigma_rad"])}
    out["joint_noise_mm"] = math.sqrt(float(joint2.sum()))
    out["declared_shape_scale"] = ev.shape["declared_scale"]
    if ev.jitter_rad is not None:
        out["readback_jitter_deg"] = {f"J{j + 1}": math.degrees(s) for j, s in enumerate(ev.jitter_rad)}
        out["readback_jitter_mm"] = math.sqrt(float(np.sum((ev.jitter_rad * ev.lever_mm) ** 2)))
    seen = (f"held-out {R:.3f} mm vs floor {F:.3f} mm; the best layer ({ev.layer}) removes {100 * pred_share:.0f} % "
            f"of the excess on held-out points (t = {ev.layer_t:.1f}); nugget {math.sqrt(noise2):.3f} mm")
    if not ev.flagged:
        return Remainder("none", math.sqrt(excess2), R, F, None, f"at the noise floor ({seen})", out)
    by_layer = pred_share >= STRUCTURE_SHARE and ev.layer_t >= PREDICT_T
    if by_layer or neigh_share >= STRUCTURE_SHARE:
        by = (f"{ev.layer} predicts {100 * pred_share:.0f} % of it on held-out points" if by_layer
              else f"neighbouring poses along {ev.neighbour_along} predict {100 * neigh_share:.0f} % of it")
        return Remainder("structure", math.sqrt(excess2), R, F, None,
                         f"{math.sqrt(excess2):.3f} mm RMS over the floor that something predicts ({by}; "
                         f"{seen})", out)
    source = _source(ev, joint2, out)
    return Remainder("noise", math.sqrt(excess2), R, F, source,
                     f"{math.sqrt(excess2):.3f} mm RMS over the floor that nothing in the pose predicts "
                     f"({seen}); likely source: {source}", out)


def _source(ev: RemainderEvidence, joint2: np.ndarray, out: dict) -> str:
    """The likely source of a noise excess: the joint readings (joint-shaped), else an under-declared floor
    (specs) or the tracker (beyond the repeat spread)."""
    declared_extra = max(ev.shape["declared_mm2"] - ev.F**2, 0.0)
    total = float(joint2.sum()) + declared_extra
    if total > 0 and joint2.sum() >= JOINT_SHARE * total:
        big = [j for j in range(len(joint2)) if joint2[j] >= 0.1 * joint2.sum()]
        js = ", ".join(f"J{j + 1} {math.degrees(ev.shape['joint_sigma_rad'][j]):.4f} deg" for j in big)
        text = f"noisy joint readings ({js} RMS: the excess moves the SMR along those joints)"
        if "readback_jitter_mm" in out:
            text += (f"; read-back minus commanded scatters by {out['readback_jitter_mm']:.3f} mm at the SMR "
                     "(" + ", ".join(f"J{j + 1} {math.degrees(ev.jitter_rad[j]):.4f} deg" for j in big) + ")")
        else:
            text += "; log the commanded joints (qc1..qcn) to confirm"
        return text
    if ev.floor_source == "specs":
        return ("floor under-declared: the tracker or the robot's repeatability is noisier than the specifications "
                "(the excess has the shape of the declared noise); measure repeated poses")
    return ("the tracker: scatter between poses beyond the repeat spread (SMR re-seating, air, line of sight), shaped "
            "like the declared noise, not like the joints")
