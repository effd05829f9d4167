"""The trend + GPR residual layer (kind ``"trend_gpr"``): a quadratic trend of the residual over the workspace, then
the GPR layer over the joints on what the trend leaves.

A GP over six joint angles learns little from a few dozen poses; a smooth error over the workspace (a sag growing
with the reach, a slow scale or tilt of the cell) is carried by ten coefficients per base-frame axis, which 50 poses
determine. The trend is a least-squares fit of ``1, x, y, z, x^2, y^2, z^2, xy, xz, yz`` (metres about the training
centroid) to the residuals at the model's SMR positions, minimum-norm where the poses leave a direction undetermined
(a planar grid); the GP then models what is left. A quadratic grows without bound away from its data, so the trend
is evaluated at the nearest point of the box of its fitted positions widened by ``TREND_MARGIN`` of its size on
each side: beyond it, the trend is held at its value on that box's face. Offered to the CV choice like every layer (``choice.choose_layer``)
up to ``TREND_MAX_ROWS`` calibration rows: beyond, the GP layers alone have the poses to learn the same structure.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gp import MultiOutputGP
from .gp_layer import GPRResidual, gp_inputs

TREND_TERMS = ("1", "x", "y", "z", "x^2", "y^2", "z^2", "xy", "xz", "yz")
TREND_MAX_ROWS = 3000           # offered up to this many calibration rows (robocal.layers.sparse_gp.EXACT_MAX_POINTS)
TREND_MARGIN = 0.1              # the trend is held constant beyond its data's box widened by this fraction per side


def trend_features(p_base_mm: np.ndarray, centre_mm: np.ndarray) -> np.ndarray:
    """(N, 10) quadratic terms ``TREND_TERMS`` of base-frame positions p_base_mm (N, 3) in metres about centre_mm."""
    x, y, z = ((np.atleast_2d(np.asarray(p_base_mm, float)) - centre_mm) / 1000.0).T
    return np.column_stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, x * z, y * z])


@dataclass(frozen=True, eq=False)
class QuadraticTrend:
    """A quadratic field over the base frame: residual (N, 3) mm = ``trend_features(p) @ coef_mm`` (coef_mm (10, 3),
    mm per m^k of each term), evaluated inside the box lo_mm..hi_mm (3,) (positions beyond are moved to its face);
    ``fit_rms_mm`` its 3-D RMS over the rows it was fitted on (its size, for the report)."""
    centre_mm: np.ndarray
    coef_mm: np.ndarray
    lo_mm: np.ndarray
    hi_mm: np.ndarray
    fit_rms_mm: float | None = None

    @classmethod
    def fit(cls, p_base_mm: np.ndarray, e_base_mm: np.ndarray) -> "QuadraticTrend":
        """Least squares (minimum norm where undetermined) of residuals e_base_mm (N, 3) at p_base_mm (N, 3)."""
        p = np.atleast_2d(np.asarray(p_base_mm, float))
        centre = p.mean(axis=0)
        F = trend_features(p, centre)
        coef = np.linalg.lstsq(F, np.asarray(e_base_mm, float), rcond=1e-8)[0]
        lo, hi = p.min(axis=0), p.max(axis=0)
        margin = TREND_MARGIN * (hi - lo)
        return cls(centre, coef, lo - margin, hi + margin, float(np.sqrt(np.mean(np.sum((F @ coef) ** 2, axis=1)))))

    def predict(self, p_base_mm: np.ndarray) -> np.ndarray:
        """The trend (N, 3) mm at base-frame positions p_base_mm (N, 3), held at the box's face beyond it."""
        p = np.clip(np.atleast_2d(np.asarray(p_base_mm, float)), self.lo_mm, self.hi_mm)
        return trend_features(p, self.centre_mm) @ self.coef_mm

    def to_dict(self) -> dict:
        return {"terms": list(TREND_TERMS), "centre_mm": self.centre_mm.tolist(), "coef_mm": self.coef_mm.tolist(),
                "lo_mm": self.lo_mm.tolist(), "hi_mm": self.hi_mm.tolist(), "fit_rms_mm": self.fit_rms_mm}

    @classmethod
    def from_dict(cls, d: dict) -> "QuadraticTrend":
        if list(d.get("terms", [])) != list(TREND_TERMS):
            raise ValueError(f"unknown trend terms {d.get('terms')!r} (expected {list(TREND_TERMS)})")
        coef = np.asarray(d["coef_mm"], float)
        if coef.shape != (len(TREND_TERMS), 3):
            raise ValueError(f"trend coef_mm has shape {coef.shape}, expected ({len(TREND_TERMS)}, 3)")
        rms = d.get("fit_rms_mm")
        box = [np.asarray(d[k], float).reshape(3) for k in ("centre_mm", "lo_mm", "hi_mm")]
        return cls(box[0], coef, box[1], box[2], None if rms is None else float(rms))


@dataclass(frozen=True, eq=False)
class TrendGPRResidual(GPRResidual):
    """The GPR layer on what a quadratic trend leaves: residual = trend(p_base) + GP(q [, payload]). The predictive
    standard deviation is the GP's (the trend's own uncertainty is not in it)."""
    trend: QuadraticTrend | None = None

    kind = "trend_gpr"

    def predict(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None) -> np.ndarray:
        """Predicted residual (N, 3) mm in the base frame at joint angles q_rad (N, n) and the model's SMR positions
        p_base_mm (N, 3)."""
        if p_base_mm is None:
            raise ValueError("the trend layer needs the model's SMR positions (p_base_mm)")
        return self.trend.predict(p_base_mm) + super().predict(q_rad, None, payload_kg)

    def with_payload(self, payload_kg: float | None) -> "TrendGPRResidual":
        return TrendGPRResidual(self.gp, self.uses_payload, payload_kg, self.trend)

    def to_dict(self) -> dict:
        return {**super().to_dict(), "kind": self.kind, "trend": self.trend.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "TrendGPRResidual":
        g = GPRResidual.from_dict(d)
        return cls(g.gp, g.uses_payload, g.payload_kg, QuadraticTrend.from_dict(d["trend"]))


def fit_trend_gpr(q_rad: np.ndarray, p_base_mm: np.ndarray, e_base_mm: np.ndarray, payload_kg=None, seed: int = 0,
                  noise_floor_mm: float | None = None, fold: np.ndarray | None = None):
    """(the trend + GPR layer of residuals e_base_mm (N, 3) at joint angles q_rad (N, n) and model SMR positions
    p_base_mm (N, 3), its k-fold held-out errors (N, 3) mm or None without ``fold``). Each fold refits the trend
    and the GP's shared hyperparameters on its training rows (warm-started from the fit on all rows). Beyond
    ``TREND_MAX_ROWS`` rows (a config that forces the layer), the layer is fitted on a seeded subset of that many."""
    X = gp_inputs(q_rad, payload_kg)
    p, e = np.asarray(p_base_mm, float), np.asarray(e_base_mm, float)
    if fold is None and len(X) > TREND_MAX_ROWS:
        sub = np.sort(np.random.default_rng(seed).choice(len(X), TREND_MAX_ROWS, replace=False))
        X, p, e = X[sub], p[sub], e[sub]
    trend = QuadraticTrend.fit(p, e)
    gp = MultiOutputGP.fit_subset(X, e - trend.predict(p), seed=seed, noise_floor_mm=noise_floor_mm)
    layer = TrendGPRResidual(gp, payload_kg is not None, None, trend)
    if fold is None:
        return layer, None
    err = np.empty_like(e)
    for k in np.unique(fold):
        tr, te = fold != k, fold == k
        t = QuadraticTrend.fit(p[tr], e[tr])
        g = MultiOutputGP.fit_subset(X[tr], e[tr] - t.predict(p[tr]), n_restarts=0, seed=seed, max_iter=40,
                                     log_theta0=gp.shared_log_theta, noise_floor_mm=noise_floor_mm)
        err[te] = e[te] - t.predict(p[te]) - g.predict(X[te])
    return layer, err
