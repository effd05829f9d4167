"""Scoring of one candidate at the current fit: greedy BIC choice of its groups, F test, blocked CV, physical
plausibility, the reach-split consistency check and the conditional ΔBIC used by the saturation/nested tests."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .candidates import Candidate, Group, Profile
from .engine import _absorption, _Engine, _lstsq_scaled, _orth, _rms, _State
from .records import DiagnosisInput, DiagnosisOptions


@dataclass(eq=False)
class _Score:
    cand: Candidate
    profile: Profile | None = None
    groups: tuple = ()
    delta_bic: float = np.inf
    delta_rss: float = 0.0
    rank: int = 0
    f_stat: float = float("nan")
    p_value: float = 1.0
    absorbed: float = float("nan")         # of the chosen profile
    absorbed_min: float = float("nan")     # of the most visible profile: decides whether it is diagnosable
    U: np.ndarray | None = None            # orthonormal visible subspace of the selected groups
    gamma: np.ndarray | None = None        # linear estimate of the selected parameters
    cv: dict | None = None
    plausible: tuple[bool, str] | None = None
    rejected: str = ""
    backward_delta_bic: float = float("nan")
    split_rejected: str = ""               # dropped as a stand-in for structure outside the library
    pruned: list = field(default_factory=list)     # group labels dropped in the backward pass
    refit_cv_t: float = float("nan")
    steps: list = field(default_factory=list)      # 1-based selection steps that added groups of this effect
    physical: dict = field(default_factory=dict)    # physical parameters (stiffness, lag, half-widths)
    shadowed: list = field(default_factory=list)    # better-scored candidates rejected by a gate, overlapping
    confusable: list = field(default_factory=list)
    extensions: list = field(default_factory=list)

    @property
    def joints(self) -> tuple[int, ...]:
        """Joints of the selected groups (1-based); with none selected, the candidate's joints (time effects:
        none, their groups are link lengths and zero drifts)."""
        js = tuple(sorted({j for g in self.groups for j in g.joints}))
        if js or self.cand.time_effect:
            return js
        return self.cand.joints


def _greedy(blocks, y, rss0, n, lnn, extra, rank_tol=1e-3, margin=0.0):
    """Forward selection of column blocks (each (3m, k), already orthogonal to the base model) by BIC; blocks
    after the first must lower BIC by ``margin``. Returns (chosen indices, ΔBIC, ΔRSS, rank, U)."""
    chosen, S = [], np.zeros((len(y), 0))
    rss, best, r_tot = rss0, 0.0, 0
    look = 2.0 * math.log(len(blocks)) if len(blocks) > 1 else 0.0     # prior 1/G on which group: look-elsewhere
    y_res = y.copy()
    while len(chosen) < len(blocks):
        trial = None
        for i, Z in enumerate(blocks):
            if i in chosen:
                continue
            Zs = Z - S @ (S.T @ Z)
            if Zs.shape[1] == 1:                      # one column: its direction, no SVD needed
                nz = float(np.linalg.norm(Zs))
                Ug = Zs / nz if nz > rank_tol else Zs[:, :0]
            else:
                U, s, _ = np.linalg.svd(Zs, full_matrices=False)
                Ug = U[:, s > rank_tol]
            if Ug.shape[1] == 0:
                continue
            d = float(np.sum((Ug.T @ y_res) ** 2))
            bic = n * math.log(max(rss - d, 1e-300) / rss0) + (r_tot + Ug.shape[1] + extra) * lnn + look
            if trial is None or bic < trial[0]:
                trial = (bic, i, Ug, d)
        if trial is None or trial[0] >= best - (margin if chosen else 0.0):
            break
        best, i, Ug, d = trial
        chosen.append(i)
        S = np.column_stack([S, Ug])
        y_res = y_res - Ug @ (Ug.T @ y_res)
        rss -= d
        r_tot += Ug.shape[1]
    return chosen, best, rss0 - rss, r_tot, S


class _Selector:
    """Forward stepwise selection over the candidates at one dataset."""

    def __init__(self, eng: _Engine, inp: DiagnosisInput, opt: DiagnosisOptions):
        self.eng, self.inp, self.opt = eng, inp, opt
        self.rows = eng.fit_rows
        self.n = 3 * len(self.rows)
        self.lnn = math.log(self.n)

    def base(self, st: _State):
        """Orthonormal basis of the current design and the residual orthogonal to it."""
        A = self.eng.design(st, self.rows)
        Q = _orth(A)
        y = self.eng.wflat(self.eng.resid(st), self.rows)
        return Q, y - Q @ (Q.T @ y), A

    def score(self, cand: Candidate, st: _State, Q, y, Qgeo) -> _Score:
        rss0 = float(y @ y)
        best = _Score(cand)
        absorbed_min = 1.0
        cache: dict[int, np.ndarray] = {}
        for prof in cand.profiles:
            X = [self.whitened(st, g, cache) for g in prof.groups]
            blocks = []
            for Xg in X:
                nrm = np.linalg.norm(Xg, axis=0)
                Z = Xg / np.where(nrm > 1e-300, nrm, 1.0)
                blocks.append(Z - Q @ (Q.T @ Z))
            absorbed = _absorption(X, Qgeo)
            absorbed_min = min(absorbed_min, absorbed)
            chosen, dbic, drss, rank, U = _greedy(blocks, y, rss0, self.n, self.lnn, cand.scan,
                                                  margin=self.opt.group_bic_margin)
            if not chosen:                       # report the whole candidate (ΔBIC > 0: not supported)
                chosen = list(range(len(blocks)))
                U = _orth(np.concatenate(blocks, axis=1), 1e-3)
                rank = U.shape[1]
                drss = float(np.sum((U.T @ y) ** 2))
                dbic = self.n * math.log(max(rss0 - drss, 1e-300) / rss0) + (rank + cand.scan) * self.lnn
            if dbic < best.delta_bic or best.profile is None:
                best = _Score(cand, prof, tuple(prof.groups[i] for i in chosen), dbic, drss, rank, U=U)
                best.absorbed = absorbed
        best.absorbed_min = absorbed_min
        if best.rank > 0:
            dof = self.n - Q.shape[1] - best.rank
            best.f_stat = (best.delta_rss / best.rank) / max((rss0 - best.delta_rss) / max(dof, 1), 1e-300)
            best.p_value = float(stats.f.sf(best.f_stat, best.rank, max(dof, 1)))
            Xs = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows)
                                 for g in best.groups], axis=1)
            best.gamma = _lstsq_scaled(Xs - Q @ (Q.T @ Xs), y, rcond=1e-6)
        else:
            best.delta_bic, best.groups = 0.0, ()
        return best

    def whitened(self, st: _State, g: Group, cache: dict) -> np.ndarray:
        """Whitened calibration-row regressor (3m, k) of a group; a profile-scaled group reuses its base's."""
        if g.base is None:
            return self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows)
        key = id(g.base)
        if key not in cache:
            cache[key] = self.eng.wflat(self.eng.regressor(st.J, st.kin, g.base), self.rows)
        return cache[key] * np.repeat(g.u[self.rows], 3)[:, None]

    def cross_validate(self, st: _State, sc: _Score) -> dict:
        """Blocked K-fold CV of the linear model with and without the candidate's selected groups."""
        by_time = sc.cand.time_effect and self.inp.t_s is not None
        folds = self.eng.folds(by_time, self.inp.t_s, self.opt.cv_folds, self.opt.seed)
        A0 = self.eng.design(st, self.rows)
        A1 = self.eng.design(st, self.rows, sc.groups)
        y = self.eng.wflat(self.eng.resid(st), self.rows)
        e0, e1 = self.eng.cv_errors(A0, y, folds), self.eng.cv_errors(A1, y, folds)
        d = np.sum(e0**2, axis=1) - np.sum(e1**2, axis=1)
        t = float(np.mean(d) / max(np.std(d, ddof=1) / math.sqrt(len(d)), 1e-300))
        b, a = _rms(self.eng.to_mm(e0, self.rows)), _rms(self.eng.to_mm(e1, self.rows))
        floor = self.inp.noise_floor_mm * math.sqrt(1.0 + self.opt.cv_param_inflation * A1.shape[1] / len(y))
        excess = max(b**2 - floor**2, self.opt.cv_excess_min_share * b**2)
        frac = (b**2 - a**2) / excess
        return {"cv_rms_before_mm": b, "cv_rms_after_mm": a, "cv_gain_t": t, "excess_explained": frac,
                "cv_blocking": "time" if by_time else "pose", "cv_folds": len(folds),
                "ok": bool(np.mean(d) > 0 and t >= self.opt.cv_min_t and frac >= self.opt.min_excess_fraction)}

    def plausibility(self, st: _State, sc: _Score) -> tuple[bool, str]:
        if sc.cand.name in ("joint_compliance", "payload_deflection") and "torque_nm" in sc.cand.info:
            return self._physical_compliance(sc)
        at, problems = 0, []
        for g in sc.groups:
            th = sc.gamma[at:at + g.k]
            at += g.k
            lim = np.broadcast_to(np.asarray(g.limit, float), (g.k,))
            for name, v, L in zip(g.names, th, lim):
                if abs(v) > L:
                    problems.append(f"|{name}| = {abs(v):.3g} > {L:.3g}")
            if g.dq is not None:
                dq = np.abs(g.dq[self.rows] @ th).max()
                if dq > g.dq_limit:
                    problems.append(f"implied joint deflection {np.degrees(dq) * 60:.1f} arcmin > "
                                    f"{np.degrees(g.dq_limit) * 60:.1f} arcmin")
        return (not problems, "; ".join(problems) if problems else "within physical bounds")


    def _physical_compliance(self, sc: _Score) -> tuple[bool, str]:
        """Judge compliance on physical parameters: the fitted deflection of each joint (whatever groups carry it)
        regressed on the physical gravity torque gives the compliance c (rad/N*m) and stiffness k = 1/c; k must be
        at least the size-derived floor. Coefficients of a general basis are never judged on their own."""
        rows = self.rows
        tau = sc.cand.info["torque_nm"]
        k_min = sc.cand.info["stiffness_min_nm_per_rad"]
        dq = np.zeros((len(rows), self.inp.q_rad.shape[1]))
        at = 0
        for g in sc.groups:
            dq += g.dq[rows] @ sc.gamma[at:at + g.k]
            at += g.k
        problems, values = [], {}
        for j in sorted({j for g in sc.groups for j in g.joints}):
            t = tau[rows, j - 1]
            A = np.column_stack([t, np.ones(len(t))])
            c = float(np.linalg.lstsq(A, dq[:, j - 1], rcond=None)[0][0])
            k = 1.0 / c if abs(c) > 1e-300 else np.inf
            defl = abs(c) * float(np.ptp(t))
            values[j] = (k, defl)
            if abs(k) < k_min:
                problems.append(f"J{j} stiffness {abs(k):.3g} N*m/rad < {k_min:.3g} (size floor)")
        sc.physical = {f"J{j}": {"stiffness_nm_per_rad": k, "deflection_range_arcmin": np.degrees(d) * 60.0}
                       for j, (k, d) in values.items()}
        desc = "; ".join(f"J{j} k = {k:.3g} N*m/rad ({np.degrees(d) * 60:.2f}' over the data)"
                         for j, (k, d) in values.items())
        neg = [j for j, (k, _) in values.items() if k < 0]
        if neg:
            desc += f"; negative on J{', J'.join(map(str, neg))} (balancer over-compensation or another effect)"
        return (not problems, "; ".join(problems) if problems else desc)

    def split_consistency(self, st: _State, sc: _Score, exclude=None) -> dict:
        """Effect-agnostic stability check: fit geometry + the candidate on the near and the far half of the poses
        (horizontal reach below / above its median) and compare the candidate's parameters (Wald χ², k dof). A
        physical effect has one set of parameters; a proxy for structure along the reach does not."""
        rows = self.rows
        T = st.kin.T_tracker_base
        pb = (st.pred[rows] - T[:3, 3]) @ T[:3, :3]
        reach = np.hypot(pb[:, 0], pb[:, 1])
        A0 = self.eng.design(st, rows)
        y = self.eng.wflat(self.eng.resid(st), rows)
        if exclude is not None:                  # sc is in the model: take its columns out, add its part back
            cols, th = exclude
            y = y + A0[:, cols] @ th
            keep = np.ones(A0.shape[1], bool)
            keep[cols] = False
            A0 = A0[:, keep]
        X = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), rows) for g in sc.groups], axis=1)
        k = X.shape[1]
        est = []
        for half in (reach < np.median(reach), reach >= np.median(reach)):
            r3 = np.repeat(half, 3)
            M = np.concatenate([A0[r3], X[r3]], axis=1)
            nrm = np.linalg.norm(M, axis=0)
            nrm[nrm < 1e-300] = 1.0
            Ms = M / nrm
            beta = np.linalg.lstsq(Ms, y[r3], rcond=1e-10)[0]
            res = y[r3] - Ms @ beta
            s2 = float(res @ res) / max(int(r3.sum()) - M.shape[1], 1)
            C = s2 * np.linalg.pinv(Ms.T @ Ms)
            est.append(((beta / nrm)[-k:], (C / np.outer(nrm, nrm))[-k:, -k:]))
        d = est[0][0] - est[1][0]
        W = float(d @ np.linalg.pinv(est[0][1] + est[1][1]) @ d)
        Q0 = _orth(A0)
        Xv = X - Q0 @ (Q0.T @ X)                                        # the visible part of the effect
        full = _lstsq_scaled(np.concatenate([A0, X], axis=1), y)[-k:]
        ratio = float(np.linalg.norm(Xv @ d) / max(np.linalg.norm(Xv @ full), 1e-300))
        return {"chi2": W, "dof": k, "p_value": float(stats.chi2.sf(W, k)), "difference_ratio": ratio}

    def given(self, st: _State, sc: _Score, other_groups, Q, y) -> float:
        """ΔBIC of sc's groups once ``other_groups`` are in the model (both orthogonalised against Q)."""
        X = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows) for g in other_groups],
                           axis=1)
        P = _orth(X - Q @ (Q.T @ X), 1e-3)
        Z = np.concatenate([self.eng.wflat(self.eng.regressor(st.J, st.kin, g), self.rows) for g in sc.groups], axis=1)
        Z = Z - Q @ (Q.T @ Z)
        Z = Z - P @ (P.T @ Z)
        U = _orth(Z, 1e-3)
        y2 = y - P @ (P.T @ y)
        rss0 = float(y2 @ y2)
        d = float(np.sum((U.T @ y2) ** 2))
        return self.n * math.log(max(rss0 - d, 1e-300) / rss0) + U.shape[1] * self.lnn

    def half_widths(self, st: _State, sc: _Score) -> dict:
        """Approach-direction offset (half-width, arcmin) of each joint's residual by size of the last move:
        constant for backlash (it saturates), growing with the move for a read-back lag."""
        rows = self.rows
        move = self.inp.meta()["move"][rows]
        appr = self.inp.approach
        if appr is None:
            return {}
        r = self.eng.resid(st)[rows]
        Jq = st.J[rows][:, :, self.eng.joint_cols]
        out = {}
        edges = (0.0, 10.0, 30.0, 60.0, 100.0, np.inf)
        for j in sorted({j for g in sc.groups for j in g.joints}):
            jq = Jq[:, :, j - 1]
            x = np.einsum("ni,ni->n", r, jq) / np.maximum(np.einsum("ni,ni->n", jq, jq), 1e-12)   # rad
            s, m = np.asarray(appr)[rows, j - 1], np.degrees(np.abs(move[:, j - 1]))
            bins = {}
            for lo, hi in zip(edges[:-1], edges[1:]):
                b = (m >= lo) & (m < hi)
                if np.sum(b & (s > 0)) >= 5 and np.sum(b & (s < 0)) >= 5:
                    hw = 0.5 * (np.mean(x[b & (s > 0)]) - np.mean(x[b & (s < 0)]))
                    bins[f"{lo:.0f}-{hi:.0f} deg" if np.isfinite(hi) else f">{lo:.0f} deg"] = np.degrees(hw) * 60.0
            out[f"J{j}"] = bins
        return out
