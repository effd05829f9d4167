"""The error budget: how many mm RMS of the nominal model's held-out error each cause accounts for.

Components, on the same held-out points (the test rows, else cross-validated calibration rows), each a mean of
per-point squared errors, so they add in quadrature:

* **geometry**: nominal (registered) -> kinematic calibration;
* **each accepted effect**: its Shapley value over the accepted effects (the mean, over every order of entry, of
  the drop in held-out squared error when it joins the effects before it): independent of the order the
  engine took them in, and the values sum to kinematic -> final. The intermediate models are the linearised
  geometry + effect subsets fitted on the calibration rows (``SubsetErrors``); the end points are the exact
  kinematic and final models. Exact over all 2^K subsets up to ``EXACT_MAX`` effects, else sampled orders;
* **residual layer**: final -> final + a non-parametric layer;
* **tracker noise (floor)**: the declared noise floor at those points;
* **unexplained structure** and **excess noise**: what is left above the floor, split by the share of noise in
  the remainder's excess over the floor (``robocal.diagnose.remainder``: the nugget of its neighbour variogram
  against its sill, on the calibration rows).

Intervals: percentile bootstrap over pose blocks of the held-out points (the models are not refitted: the
interval is that of the held-out evaluation). Closure: sqrt(sum of the components^2) against the nominal
held-out RMS. The chain of models telescopes, so what does not close is what had to be clipped: a component
whose mean is negative (a layer that does worse on held-out points, an effect that costs once the others are in,
a floor above the remainder), shown as 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from typing import Callable, Mapping, Sequence

import numpy as np

from robocal.effects.bases import effect_regressor
from robocal.effects.cv import design_array, pose_clusters
from robocal.kinematics.models import identification_jacobian
from .jsonable import json_float

EXACT_MAX = 8            # exact Shapley values up to this many effects (2^K subset fits), sampled orders above
ORDERS = 48              # sampled orders of entry above EXACT_MAX
KINDS = ("geometry", "effect", "layer", "floor", "structure", "noise")
ATTRIBUTION = ("Shapley values over the accepted effects (mean drop of the held-out squared error over every "
               "order of entry; linearised subset fits, exact end points)")


@dataclass(frozen=True)
class BudgetComponent:
    """One cause: RMS (mm) it accounts for on the held-out points and its bootstrap interval (low, high)."""
    name: str
    kind: str
    rms_mm: float
    low_mm: float
    high_mm: float

    def to_dict(self) -> dict:
        return {"name": self.name, "kind": self.kind, "rms_mm": json_float(self.rms_mm), "low_mm": json_float(self.low_mm),
                "high_mm": json_float(self.high_mm)}

    @classmethod
    def from_dict(cls, d: Mapping) -> "BudgetComponent":
        return cls(str(d["name"]), str(d.get("kind", "")), _n(d["rms_mm"]), _n(d["low_mm"]), _n(d["high_mm"]))


@dataclass(frozen=True)
class ErrorBudget:
    """The budget: components in the order nominal -> floor, the nominal held-out RMS, the quadrature sum of the
    components and ``closure`` = |sum - nominal| / nominal; how the points were held out, how the effects were
    attributed and what the interval is."""
    components: tuple[BudgetComponent, ...]
    nominal_rms_mm: float
    sum_rms_mm: float
    closure: float
    evaluation: str            # "test" | "cv"
    n_points: int
    attribution: str
    interval: str

    def component(self, name: str) -> BudgetComponent | None:
        return next((c for c in self.components if c.name == name), None)

    def of_kind(self, kind: str) -> tuple[BudgetComponent, ...]:
        return tuple(c for c in self.components if c.kind == kind)

    def to_dict(self) -> dict:
        return {"components": [c.to_dict() for c in self.components], "nominal_rms_mm": json_float(self.nominal_rms_mm),
                "sum_rms_mm": json_float(self.sum_rms_mm), "closure": json_float(self.closure), "evaluation": self.evaluation,
                "n_points": int(self.n_points), "attribution": self.attribution, "interval": self.interval}

    @classmethod
    def from_dict(cls, d: Mapping) -> "ErrorBudget":
        return cls(tuple(BudgetComponent.from_dict(c) for c in d["components"]), _n(d["nominal_rms_mm"]),
                   _n(d.get("sum_rms_mm")), _n(d["closure"]), str(d.get("evaluation", "")), int(d.get("n_points", 0)),
                   str(d.get("attribution", "")), str(d.get("interval", "")))


def _n(x) -> float:
    return float("nan") if x is None else float(x)


# ============================================================================ linearised subsets
def linear_design(kin_geo, geo_cols: np.ndarray, q_rad: np.ndarray, meta: Mapping, effects
                  ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """(p0 (N, 3) tracker mm at the geometric solution, A (N, 3, P) = [geometric columns | each effect's
    regressor] from ``design_array`` (parameter-major), the effects' regressors (N, 3, K_k), their column
    ranges) of the fitted effects ``effects`` (FittedEffect) at q_rad (N, n)."""
    p0, J = identification_jacobian(kin_geo, q_rad)
    R = [effect_regressor(kin_geo, q_rad, meta, fe.choice.build(kin_geo.n), jacobian=(p0, J)) for fe in effects]
    A = design_array(len(q_rad), len(geo_cols) + sum(r.shape[2] for r in R))
    A[:, :, :len(geo_cols)] = J[:, :, geo_cols]
    at, cols = len(geo_cols), []
    for r in R:
        A[:, :, at:at + r.shape[2]] = r
        cols.append(np.arange(at, at + r.shape[2]))
        at += r.shape[2]
    return p0, A, R, cols


class SubsetErrors:
    """Held-out error vectors of geometry + a subset of the effects, linearised at the geometric solution: a
    weighted least-squares fit on the calibration rows (``cv``: their ``BlockedCV``), evaluated on other rows
    (``A_ev`` (M, 3, P), ``y_ev`` (M, 3) mm: measured - p0), or, without them, cross-validated on the
    calibration rows (mean squared error over the blockings, as the engine). ``n_geo`` geometric columns,
    ``eff_cols`` each effect's columns."""

    def __init__(self, cv, n_geo: int, eff_cols: Sequence[np.ndarray], A_ev: np.ndarray | None = None,
                 y_ev: np.ndarray | None = None):
        self.cv, self.n_geo, self.eff_cols, self.A_ev, self.y_ev = cv, n_geo, list(eff_cols), A_ev, y_ev

    def cols(self, subset: Sequence[int]) -> np.ndarray:
        return np.concatenate([np.arange(self.n_geo)] + [self.eff_cols[k] for k in subset]).astype(int)

    def squared(self, subset: Sequence[int]) -> np.ndarray:
        """(M,) mm^2 held-out squared errors of geometry + the effects ``subset`` (indices into ``eff_cols``)."""
        cols = self.cols(subset)
        if self.A_ev is None:
            return np.mean(np.stack(list(self.cv.squared_errors(cols).values())), axis=0)
        e = self.y_ev - self.A_ev[:, :, cols] @ self.cv.fit(cols)
        return np.sum(e**2, axis=1)


# ============================================================================ attribution
def shapley(err2: Callable[[tuple[int, ...]], np.ndarray], k: int, first: np.ndarray, last: np.ndarray,
            seed: int = 0) -> np.ndarray:
    """Per-point Shapley values (M, k) of k players whose coalition S has per-point squared errors ``err2(S)``
    (M,), with the end points given: ``first`` (no player) and ``last`` (all). Row sums equal first - last."""
    M = len(first)
    if k == 0:
        return np.zeros((M, 0))
    full = tuple(range(k))
    cache: dict[tuple[int, ...], np.ndarray] = {(): np.asarray(first, float), full: np.asarray(last, float)}

    def value(S: tuple[int, ...]) -> np.ndarray:
        if S not in cache:
            cache[S] = err2(S)
        return cache[S]
    phi = np.zeros((M, k))
    if k <= EXACT_MAX:
        w = [math.factorial(s) * math.factorial(k - s - 1) / math.factorial(k) for s in range(k)]
        for s in range(k):
            for S in combinations(full, s):
                base = value(S)
                for j in set(full) - set(S):
                    phi[:, j] += w[s] * (base - value(tuple(sorted(S + (j,)))))
        return phi
    rng = np.random.default_rng(seed)
    for _ in range(ORDERS):
        S: tuple[int, ...] = ()
        prev = value(S)
        for j in rng.permutation(k):
            S = tuple(sorted(S + (int(j),)))
            cur = value(S)
            phi[:, j] += prev - cur
            prev = cur
    return phi / ORDERS


# ============================================================================ the budget
@dataclass(frozen=True, eq=False)
class BudgetTerms:
    """Per-point squared errors (M,) mm^2 on the held-out points of the chain of models, and what splits them:
    ``phi`` (M, K) the effects' Shapley values (``names`` K labels), ``layer`` None without a layer, ``floor2``
    the declared floor at each point, ``noise_share`` the share of the remainder above the floor that is noise
    (``robocal.diagnose.remainder``), ``q_rad`` (M, n) the points' joints (bootstrap blocks)."""
    nominal: np.ndarray
    kinematic: np.ndarray
    phi: np.ndarray
    names: tuple[str, ...]
    final: np.ndarray
    layer: np.ndarray | None
    layer_name: str
    floor2: np.ndarray
    noise_share: float
    q_rad: np.ndarray
    evaluation: str


def per_point(t: BudgetTerms) -> tuple[list[tuple[str, str]], np.ndarray]:
    """((name, kind) per component, D (M, C) per-point contributions, mm^2): every row sums to the nominal
    squared error."""
    after = t.final if t.layer is None else t.layer
    rest = after - t.floor2
    noise_share = float(np.clip(t.noise_share, 0.0, 1.0))
    cols = [t.nominal - t.kinematic] + [t.phi[:, k] for k in range(t.phi.shape[1])]
    names = [("geometry (nominal -> kinematic)", "geometry")] + [(n, "effect") for n in t.names]
    if t.layer is not None:
        cols.append(t.final - t.layer)
        names.append((f"residual layer ({t.layer_name})", "layer"))
    cols += [t.floor2, (1.0 - noise_share) * rest, noise_share * rest]
    names += [("tracker noise (floor)", "floor"), ("unexplained structure", "structure"), ("excess noise", "noise")]
    return names, np.stack(cols, axis=1)


def error_budget(t: BudgetTerms, boot: int = 400, level: float = 0.95, seed: int = 0) -> ErrorBudget:
    """The budget of ``t`` with a percentile bootstrap over pose blocks of the held-out points."""
    names, D = per_point(t)
    M = len(D)
    mean = D.mean(axis=0)
    rms = np.sqrt(np.clip(mean, 0.0, None))
    block = pose_clusters(t.q_rad, int(np.clip(M // 20, 1, 12)), seed)
    low, high = _bootstrap(D, block, boot, level, seed)
    nominal = math.sqrt(float(np.mean(t.nominal)))
    total = math.sqrt(float(np.sum(rms**2)))
    comps = tuple(BudgetComponent(n, k, float(r), float(lo), float(hi))
                  for (n, k), r, lo, hi in zip(names, rms, low, high))
    nb = len(np.unique(block))
    return ErrorBudget(comps, nominal, total, abs(total - nominal) / nominal if nominal > 0 else float("nan"),
                       t.evaluation, M, ATTRIBUTION,
                       f"{100 * level:.0f} % percentile bootstrap over {nb} pose blocks of the held-out points "
                       f"({boot} resamples; the models are not refitted)")


def _bootstrap(D: np.ndarray, block: np.ndarray, boot: int, level: float, seed: int) -> tuple[np.ndarray, ...]:
    """(low, high) (C,) mm of sqrt(max(mean, 0)) of each column of D (M, C) over block resamples."""
    ids, inv = np.unique(block, return_inverse=True)
    nb = len(ids)
    S = np.zeros((nb, D.shape[1]))
    np.add.at(S, inv, D)
    n = np.bincount(inv, minlength=nb).astype(float)
    counts = np.random.default_rng(seed).multinomial(nb, np.full(nb, 1.0 / nb), size=boot).astype(float)
    means = (counts @ S) / (counts @ n)[:, None]
    r = np.sqrt(np.clip(means, 0.0, None))
    a = 100.0 * (1.0 - level) / 2.0
    return np.percentile(r, a, axis=0), np.percentile(r, 100.0 - a, axis=0)


@dataclass(frozen=True, eq=False)
class HeldOut:
    """The held-out rows of a calibrated chain: joints (M, n) rad, measured (M, 3) tracker mm, their effects'
    metadata, and the squared errors (M,) mm^2 of the nominal, kinematic, final (+ effects) models and of the
    final model with its residual layer (None: no layer, named ``layer_name``); ``floor2`` (M,) the declared
    floor^2 at each."""
    q_rad: np.ndarray
    p_mm: np.ndarray
    meta: Mapping
    nominal: np.ndarray
    kinematic: np.ndarray
    final: np.ndarray
    layer: np.ndarray | None
    layer_name: str
    floor2: np.ndarray


def model_budget(kin_geo, geo_cols: np.ndarray, q_fit: np.ndarray, p_fit: np.ndarray, cov_fit: np.ndarray,
                 meta_fit: Mapping, effects, r_final_fit: np.ndarray, n_params: int, held: HeldOut,
                 folds: int = 5, seed: int = 0) -> ErrorBudget:
    """The budget of a calibration (``reprocess``): the effects' Shapley values from the linearised geometry +
    effects fitted on the fit rows (``q_fit``, ``p_fit``, ``cov_fit``, ``meta_fit`` of the geometric model
    ``kin_geo`` with identified columns ``geo_cols``) evaluated at the held-out rows; the noise share from the
    nugget of the final model's fit residuals ``r_final_fit`` (N, 3) mm (``n_params`` fitted)."""
    from robocal.effects.cv import BlockedCV, Blocking, pose_blocks
    from robocal.identify.whitened import whitening
    from .remainder import nugget

    p0, A, _, cols = linear_design(kin_geo, geo_cols, q_fit, meta_fit, effects)
    cv = BlockedCV(A, p_fit - p0, whitening(cov_fit, len(q_fit)),
                   [Blocking("pose blocks", pose_blocks(q_fit, folds, seed))], copy=False)
    del A
    p0_ev, A_ev, _, _ = linear_design(kin_geo, geo_cols, held.q_rad, held.meta, effects)
    sub = SubsetErrors(cv, len(geo_cols), cols, np.asarray(A_ev), held.p_mm - p0_ev)
    phi = shapley(sub.squared, len(effects), held.kinematic, held.final, seed)
    ng = nugget(r_final_fit, q_fit, dof_share=n_params / (3.0 * len(q_fit)))
    F2 = float(np.mean(held.floor2))
    share = (ng["nugget_mm2"] - F2) / (ng["sill_mm2"] - F2) if ng["sill_mm2"] > F2 else 0.0
    terms = BudgetTerms(held.nominal, held.kinematic, phi, tuple(fe.choice.label for fe in effects), held.final,
                        held.layer, held.layer_name, held.floor2, share, held.q_rad, "test")
    return error_budget(terms, seed=seed)
