"""The trend + GPR residual layer (kind ``"trend_gpr"``): a quadratic trend of the residual over the workspace, fitted
together with a linear correction of the identified geometry, then the GPR layer over the joints on what is left.

A GP over six joint angles learns little from a few dozen poses; a smooth error over the workspace (a sag growing
with the reach, a strain of the cell) is carried by ten coefficients per base-frame axis, which 50 poses determine.
But the geometric fit has already taken the share of such an error that its parameters can mimic, and what it
leaves is no longer a smooth field of the position. So the trend ``1, x, y, z, x^2, y^2, z^2, xy, xz, yz`` (metres
about the training centroid, at the model's SMR positions) is fitted by least squares together with a change of the
identified geometric parameters, linearised at the fitted model (the identification Jacobian, in the base frame):
the share the geometry took goes back to the trend. The two share directions (a constant and the base translation,
a linear field and the base rotation or a scale of the link lengths). Both have normal priors (the geometry's by
unit, as the pose design's: 1 mm, 1 mrad; the trend's 1 mm per m^k) against the noise floor, so the split along a
shared or undetermined direction stays small instead of growing without bound. The GP then models what is left.
Offered to the CV choice like every layer (``choice.choose_layer``) up to ``TREND_MAX_ROWS`` calibration rows: beyond,
the GP layers alone have the poses to learn the same structure.

A quadratic grows without bound away from its data, so the trend is evaluated at the nearest point of the box of its
fitted positions widened by ``TREND_MARGIN`` of its size on each side: beyond it, the trend is held at its value on
that box's face. The geometric change is linear in the parameters and bounded by its prior like the geometry.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.identify import geometric_prior_sigma
from robocal.kinematics.models import Kinematics, ParamLayout, identification_jacobian
from .gp import MultiOutputGP
from .gp_layer import GPRResidual, gp_inputs

TREND_TERMS = ("1", "x", "y", "z", "x^2", "y^2", "z^2", "xy", "xz", "yz")
TREND_MAX_ROWS = 3000           # offered up to this many calibration rows (robocal.layers.sparse_gp.EXACT_MAX_POINTS)
TREND_MARGIN = 0.1              # the trend is held constant beyond its data's box widened by this fraction per side
TREND_WITH_GEOMETRY = True      # fit the trend together with the identified geometry's change (issue 32, twelfth)
TREND_PRIOR_MM = 1.0            # prior std of each trend coefficient, mm per m^k (a sag of 1 mm at 1 m is large)


def trend_features(p_base_mm: np.ndarray, centre_mm: np.ndarray) -> np.ndarray:
    """(N, 10) quadratic terms ``TREND_TERMS`` of base-frame positions p_base_mm (N, 3) in metres about centre_mm."""
    x, y, z = ((np.atleast_2d(np.asarray(p_base_mm, float)) - centre_mm) / 1000.0).T
    return np.column_stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, x * z, y * z])


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(v**2, axis=1))))


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
    def of(cls, p_base_mm: np.ndarray, centre_mm: np.ndarray, coef_mm: np.ndarray) -> "QuadraticTrend":
        """The trend of coefficients coef_mm (10, 3) about centre_mm, fitted at positions p_base_mm (N, 3)."""
        p = np.atleast_2d(np.asarray(p_base_mm, float))
        lo, hi = p.min(axis=0), p.max(axis=0)
        margin = TREND_MARGIN * (hi - lo)
        return cls(centre_mm, coef_mm, lo - margin, hi + margin, _rms(trend_features(p, centre_mm) @ coef_mm))

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
class GeometryShift:
    """A change ``delta`` (G,) of the identified geometric parameters ``names`` of ``kinematics``, linearised: the
    SMR moves by R^T J(q)[:, :, names] @ delta (N, 3) mm in the base frame (J the tracker-frame identification
    Jacobian, mm per parameter unit); ``fit_rms_mm`` that displacement's 3-D RMS over the rows it was fitted on."""
    kinematics: Kinematics
    names: tuple[str, ...]
    delta: np.ndarray
    fit_rms_mm: float | None = None

    def columns(self, q_rad: np.ndarray) -> np.ndarray:
        """(N, 3, G) base-frame SMR displacement per unit parameter at joint angles q_rad (N, n)."""
        return geometry_columns(self.kinematics, self.names, q_rad)

    def predict(self, q_rad: np.ndarray) -> np.ndarray:
        return self.columns(q_rad) @ self.delta

    def to_dict(self) -> dict:
        layout = ParamLayout.of(self.kinematics)
        return {"kinematics": self.kinematics.to_dict(), "parameters": list(self.names),
                "units": [layout.unit(n) for n in self.names], "delta": self.delta.tolist(),
                "fit_rms_mm": self.fit_rms_mm}

    @classmethod
    def from_dict(cls, d: dict) -> "GeometryShift":
        kin = Kinematics.from_dict(d["kinematics"])
        names, delta = tuple(d["parameters"]), np.asarray(d["delta"], float)
        unknown = set(names) - set(ParamLayout.of(kin).names)
        if unknown or delta.shape != (len(names),):
            raise ValueError(f"geometry shift: parameters {sorted(unknown)} unknown or delta of shape {delta.shape} "
                             f"for {len(names)} parameters")
        rms = d.get("fit_rms_mm")
        return cls(kin, names, delta, None if rms is None else float(rms))


def geometry_columns(kin: Kinematics, names, q_rad: np.ndarray) -> np.ndarray:
    """(N, 3, G) base-frame SMR displacement per unit of the parameters ``names`` at joint angles q_rad (N, n)."""
    layout = ParamLayout.of(kin)
    _, J = identification_jacobian(kin, q_rad)
    return np.einsum("ji,njk->nik", kin.T_tracker_base[:3, :3], J[:, :, [layout.index(n) for n in names]])


@dataclass(frozen=True, eq=False)
class TrendGPRResidual(GPRResidual):
    """The GPR layer on what a quadratic trend and a geometry shift leave: residual = shift(q) + trend(p_base) +
    GP(q [, payload]); ``together_rms_mm`` the trend and the shift together over the fitted rows (each alone can be
    larger: they share directions). The predictive standard deviation is the GP's (the trend's and the shift's own
    uncertainty is not in it)."""
    trend: QuadraticTrend | None = None
    shift: GeometryShift | None = None
    together_rms_mm: float | None = None     # trend + shift, 3-D RMS over the fitted rows (they share directions)

    kind = "trend_gpr"

    def predict(self, q_rad: np.ndarray, p_base_mm: np.ndarray | None = None, payload_kg=None) -> np.ndarray:
        """Predicted residual (N, 3) mm in the base frame at joint angles q_rad (N, n) and the model's SMR positions
        p_base_mm (N, 3)."""
        if p_base_mm is None:
            raise ValueError("the trend layer needs the model's SMR positions (p_base_mm)")
        out = self.trend.predict(p_base_mm) + super().predict(q_rad, None, payload_kg)
        return out if self.shift is None else out + self.shift.predict(q_rad)

    def with_payload(self, payload_kg: float | None) -> "TrendGPRResidual":
        return TrendGPRResidual(self.gp, self.uses_payload, payload_kg, self.trend, self.shift, self.together_rms_mm)

    def to_dict(self) -> dict:
        return {**super().to_dict(), "kind": self.kind, "trend": self.trend.to_dict(),
                "geometry_shift": None if self.shift is None else self.shift.to_dict(),
                "together_rms_mm": self.together_rms_mm}

    @classmethod
    def from_dict(cls, d: dict) -> "TrendGPRResidual":
        g = GPRResidual.from_dict(d)
        shift, together = d.get("geometry_shift"), d.get("together_rms_mm")
        return cls(g.gp, g.uses_payload, g.payload_kg, QuadraticTrend.from_dict(d["trend"]),
                   None if shift is None else GeometryShift.from_dict(shift), None if together is None else float(together))


def _joint_solve(A: np.ndarray, F: np.ndarray, e: np.ndarray, prior: np.ndarray, noise_mm: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(delta (G,), coef (10, 3)): the posterior mean of the geometric change and the trend given residuals e (N, 3),
    geometric columns A (N, 3, G), trend terms F (N, 10) per axis, independent normal priors of std ``prior`` (G + 30,)
    and noise std ``noise_mm`` per axis. Bounded where the data leave a direction undetermined (the prior decides)."""
    n, g = len(e), A.shape[2]
    T = np.einsum("nj,ik->nijk", F, np.eye(3)).reshape(n, 3, 3 * F.shape[1])     # coef index j*3+k: term j, axis k
    M = np.concatenate([A, T], axis=2).reshape(3 * n, g + T.shape[2]) * prior
    H = M.T @ M
    H.flat[::len(H) + 1] += noise_mm**2
    x = np.linalg.solve(H, M.T @ e.reshape(-1)) * prior
    return x[:g], x[g:].reshape(F.shape[1], 3)


def _priors(kinematics: Kinematics | None, names) -> np.ndarray:
    """Prior std (G + 30,) of the geometric change (by unit, as the pose design's) and of the trend's terms."""
    layout = None if not names else ParamLayout.of(kinematics)
    geo = geometric_prior_sigma([layout.unit(n) for n in names]) if names else np.zeros(0)
    return np.concatenate([geo, np.full(3 * len(TREND_TERMS), TREND_PRIOR_MM)])


def fit_trend_gpr(q_rad: np.ndarray, p_base_mm: np.ndarray, e_base_mm: np.ndarray, payload_kg=None, seed: int = 0,
                  noise_floor_mm: float | None = None, fold: np.ndarray | None = None,
                  kinematics: Kinematics | None = None, names=()):
    """(the trend + GPR layer of residuals e_base_mm (N, 3) at joint angles q_rad (N, n) and model SMR positions
    p_base_mm (N, 3), its k-fold held-out errors (N, 3) mm or None without ``fold``). With ``kinematics`` and the
    identified parameter ``names``, the trend is fitted together with their linearised change. Each fold refits
    the trend, the change and the GP's shared hyperparameters on its training rows (the GP warm-started from the fit
    on all rows). Beyond ``TREND_MAX_ROWS`` rows (a config that forces the layer), the layer is fitted on a seeded
    subset of that many."""
    X = gp_inputs(q_rad, payload_kg)
    q, p, e = np.atleast_2d(np.asarray(q_rad, float)), np.asarray(p_base_mm, float), np.asarray(e_base_mm, float)
    if fold is None and len(X) > TREND_MAX_ROWS:
        sub = np.sort(np.random.default_rng(seed).choice(len(X), TREND_MAX_ROWS, replace=False))
        X, q, p, e = X[sub], q[sub], p[sub], e[sub]
    names = tuple(names) if kinematics is not None and TREND_WITH_GEOMETRY else ()
    A = geometry_columns(kinematics, names, q) if names else np.zeros((len(q), 3, 0))
    centre = p.mean(axis=0)
    F = trend_features(p, centre)
    prior = _priors(kinematics, names)
    noise = noise_floor_mm / np.sqrt(3) if noise_floor_mm else float(np.sqrt(np.mean(e**2)))
    delta, coef = _joint_solve(A, F, e, prior, noise)
    trend = QuadraticTrend.of(p, centre, coef)
    shift = GeometryShift(kinematics, names, delta, _rms(A @ delta)) if names else None
    parametric = trend.predict(p) + A @ delta
    gp = MultiOutputGP.fit_subset(X, e - parametric, seed=seed, noise_floor_mm=noise_floor_mm)
    layer = TrendGPRResidual(gp, payload_kg is not None, None, trend, shift, _rms(parametric))
    if fold is None:
        return layer, None
    err = np.empty_like(e)
    for k in np.unique(fold):
        tr, te = fold != k, fold == k
        d_k, c_k = _joint_solve(A[tr], F[tr], e[tr], prior, noise)
        t_k = QuadraticTrend.of(p[tr], centre, c_k)
        g = MultiOutputGP.fit_subset(X[tr], e[tr] - t_k.predict(p[tr]) - A[tr] @ d_k, n_restarts=0, seed=seed,
                                     max_iter=40, log_theta0=gp.shared_log_theta, noise_floor_mm=noise_floor_mm)
        err[te] = e[te] - t_k.predict(p[te]) - A[te] @ d_k - g.predict(X[te])
    return layer, err
