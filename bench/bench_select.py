"""Which selection criterion ``campaign select`` should use, judged by held-out prediction on forms it was not tuned on.

Protocol (fixed before the comparison was run; one smoke row of UR10 seen, nothing changed after):
  * Forms: the public real UR5 campaign (1000 grid rows, 100 chosen, its 20 random held-out poses) and four
    simulated cells (``simulated_cell``, seeds 1 2 3 each), every one with other effects: IRB 2600 with J2/J3
    gravity compliance + a J2 gear error; IRB 4600 with a J3 gear error + wrist coupling; UR10 geometry only;
    UR5 with a J1 gear error. The measured data set of a simulated cell is its grid plan's calibration points,
    measured once; the held-out set its plan's test points, measured separately. n = max(M / 3, 1.2 x the
    identifiable parameters) rows are chosen of the M.
  * Every subset is calibrated by the DEFAULT ``process`` of the cell's config; the score of a subset is its
    held-out RMS over the RMS of all M rows (same measurements); per form the mean over its seeds; the overall
    score of a criterion the mean over the five forms (the real campaign counts as one form).
  * Supplementary, not part of the protocol above (added after it was run): ``--forms ur5-split`` judges the UR5
    campaign on 520 held-out poses instead of 20 (``ur5_split_datasets``: seeded halves of the grid, 100 chosen
    of one half, held out the other half and the 20 random poses; one data set per seed).
  * The criterion with the lowest overall score wins; the current one (d_spread) is kept unless another beats it
    by more than 1 %. Seeded random subsets (median of 5 per data set) are the reference a criterion must beat.
  * Re-run when the default process gained the joint-error GP layer (docs/results.md): d_fx and kcenter tied
    within 0.3 % on the five forms, both more than 1 % ahead of d_spread; kcenter was taken (it uses no measured
    error, and leads on ur5-split), so ``campaign select`` now uses it (``robocal.design.optimal.space_filling``). The
    last line printed now keeps kcenter unless another is more than 1 % better.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_select.py [--seeds 1 2 3] [--criteria ...]
        [--forms ur5-real ...] [--metric rms_mm|mean_mm]

Issue 32, ``--adaptive``: adaptive replay against the landed one-shot selection and random subsets (implementation
in ``select_replay.py``, forms in ``select_forms.py``). Protocol, fixed before the comparison was run (written at
commit 867c21f + this docstring; nothing about the method, the forms or the seeds changes after the run without
being disclosed beside the figures, and a revised criterion is judged again on the fresh seeds 4 5 6):
  * Forms (seven): the public real UR5 campaign (1000 grid calibration rows, its 20 random held-out poses; one data
    set) and six simulated cells unlike each other, seeds 1 2 3 each (``select_forms.ADAPTIVE_FORMS``):
    compliance + gear + drift (truth simulator: J2/J3 gravity compliance, a gear error, tracker-registration drift;
    300 calibration poses in random order over two hours, payload blocks of 0 / 12 kg, 100 test poses among them);
    strong compliance with sparse far poses (truth simulator, compliance x 3, 85 % of the poses central in J2/J3);
    read-back lag (truth simulator); UR10-like (configs/ur10.yaml: compliance + a J2 gear error, its grid every 100
    mm, ~430 rows); IRB 4600-like (configs/irb4600.yaml: compliance + a J3 gear error + wrist coupling, grid every
    150 mm, ~570 rows); structure only a residual layer removes (truth simulator: a sag growing with the square of
    the reach, outside the effect library).
  * Methods, each at 50 and 100 calibration poses: the adaptive replay (``campaign select --adaptive``: D-optimal
    seed, then batches of 10, each chosen from the refit of the rows chosen before it; the 50-pose selection is the
    first 50 rows of the replay to 100, which is what a replay to 50 chooses: greedy picks), under each of its two
    rules (``i``: the largest fall of the model's predicted variance at the task poses; ``d``: the most information
    about the model's parameters and layer); the landed one-shot ``campaign select`` (space-filling); random subsets
    (the median of 5 seeded ones).
  * Score: held-out RMS of the DEFAULT process on the chosen rows (every other row kept, as select writes them) over
    that of all rows of the same data set; per form the mean over its seeds.
  * Choice of the rule: the lower mean over the seven forms of the mean of its two sizes' scores becomes the rule of
    ``--adaptive`` and of ``plan.kind: adaptive``. Never by the UR5 alone.
  * Goals (issue 32), for the chosen rule on every form (mean over seeds; the worst seed printed beside it): at most
    1.2 at 100 poses, at most 1.35 at 50.
  * Development before this was fixed: the method was debugged and revised on seeds 101 and 102 of the simulated
    forms only (a bug in the variance-reduction forms, and the parametric variance scaled by the noise the layer
    leaves instead of s0^2, both found there); the UR5 campaign was not run with the adaptive selection before the
    run below.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select.py --adaptive [--seeds 1 2 3]
        [--forms ...] [--rules i d] [--json OUT.json] [--combine A.json B.json]

Issue 32, revised protocol: the adaptive replay's seed (written before any revised seed was run on the judged data;
this paragraph is committed on its own, before the run). Everything above holds except what is named here.
  * What is revised, and why: only the seed set of the adaptive replay (and of ``plan.kind: adaptive``, which shares
    it: ``campaign.plan.adaptive.seed_rows`` / ``seed_size``). Rule ``d``, batches of 10, the refit, the forms, the
    score and the goals are unchanged. The first run met the goal at 100 poses on every form but not at 50: UR5
    1.663 (one-shot 1.218, random 1.477) and layer-only 1.399. Untested causes: 28 of the UR5's 50 rows are the
    D-optimal seed, and the D-optimal criterion was worse than random subsets on that campaign (issue 22) while the
    space-filling one was better; a seed of 21-30 rows leaves 2-3 rounds before 50.
  * Candidates (rule ``d``; ``--seed-designs``): (a) ``D``, today's: D-optimal seed with the joints spread, the
    identifiable geometric parameters + 10 %, at least 4 points per CV fold (simulated forms 21-30 rows, UR5 28);
    (b) ``SF``: a space-filling seed of the same size (``robocal.design.space_filling``, what ``campaign select``
    uses: farthest-first in lever-scaled joint space, D-optimal when that leaves a geometric parameter
    undetermined); (c) ``SF-small``: a space-filling seed of 4 points per CV fold (20 with the default 5 folds; at
    least the points whose three coordinates give the identifiable geometric parameters + 10 %), so more rounds
    before 50; (d) ``D-small``: the D-optimal seed of that smaller size (with (a)-(c), design x size).
  * Seeds: 4 5 6 for the six simulated forms, fresh (never run before this paragraph was committed). The UR5
    campaign is the one data set it was in the first run, so it is not fresh: (a)'s figures on it are known (1.663
    / 1.131); (b)-(d) were never run on it.
  * Choice: the lowest mean over the seven forms of the mean of the two sizes' scores (the UR5 one form among
    seven, never by it alone); (a) is kept unless another is more than 1 % lower (issue 32 asks for a D-optimal
    seed). The chosen seed becomes that of ``campaign select --adaptive`` and ``plan.kind: adaptive``. The goals
    are judged for it, as above (mean over seeds 4-6 per form, the worst seed beside), with the one-shot
    selection and random subsets on the same data sets; the first run's table stays in docs/results.md.
  * Development before this was fixed: the candidates were wired and the bench debugged on seed 101 of two
    simulated forms (layer-only, UR10-like), one run whose figures were seen and changed nothing; no revised seed
    ran on the UR5 campaign or on seeds 4-6.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select.py --adaptive --rules d
        --seed-designs D SF SF-small D-small --seeds 4 5 6 [--forms ... --json A.json] [--combine A.json B.json]

Outcome of the revised protocol (run on main 5289e97 + the two commits above; two processes, --combine; the table
is in docs/results.md): score over forms and sizes D 1.393, SF 1.161, SF-small 1.176, D-small 1.191. ``SF`` is
chosen (17 % below D; D broke down at 50 poses on seed 4 of the sparse-far-pose form, 10.57 x) and is now the seed
of ``campaign select --adaptive`` and ``plan.kind: adaptive``; ``--seed-designs`` defaults to it. The goals for it:
NOT met at 50 poses (UR5 1.508, layer-only 1.482), NOT met at 100 on the UR5 (1.237; every simulated form <= 1.119).
The first run's UR5 figure of D at 50 poses, 1.663, was of its branch (a2a2d03, which still gives it): the merge
with that session's other work (d301216) already gives 1.450, as does the code this run started from.

Issue 32, third protocol: the rule of the rounds (written before rule ``f`` or ``df`` ran on judged data; this
paragraph is committed with the code of f and df, before the run). Everything of the revised protocol holds
except what is named.
  * What is revised, and why: only the rule that picks each batch (``robocal.design.adaptive.choose_batch``;
    ``campaign.calibrate.adaptive_model.RULE``, shared by ``campaign select --adaptive`` and ``plan.kind:
    adaptive``). The seed (SF), batches of 10, the refit, the stop, the forms, the score and the goals are
    unchanged. In both runs so far the one-shot space-filling selection beat the adaptive replay on the mean over
    forms at 50 poses (1.190 against 1.251 on seeds 1-3; 1.184 against 1.229 on seeds 4-6) and on the UR5, and the
    stages measured after the second run put the UR5's gap in the residual layer, which does better on evenly
    spread poses. Whether the model-driven picks pay at all is the question.
  * Candidates (all with the SF seed; ``--rules``): (a) ``d``, today's: each pick where the refitted model learns
    most about its parameters and its layer; (b) ``f``: each pick the candidate farthest, in lever-scaled joint
    space (the metric of the seed and of ``campaign select``), from every pose measured or picked (the model then
    still gives every round's predicted gain and the stop, not the poses); (c) ``df``: the picks of ``d`` and ``f``
    in turn, ``d`` first.
  * Seeds: 7 8 9 for the six simulated forms, fresh. The UR5 campaign is not fresh: (a)'s figures on it are known
    (1.508 / 1.237); (b) continues the seed farthest-first as the one-shot selection does (1.218 / 1.073 known);
    (c) never ran on it.
  * Choice: the lowest mean over the seven forms of the mean of the two sizes' scores (the UR5 one form among
    seven); (a) is kept unless another is more than 1 % lower (the summary line prints it). The chosen rule becomes
    ``RULE``. Goals judged for it as before (mean over seeds 7-9 per form, worst seed beside), with the one-shot
    selection and random subsets on the same data sets; the earlier tables stay in docs/results.md.
  * Development before this was fixed: ``df`` was written and run on development seeds only, rules d / df /
    one-shot (held-out ratio, mean of 50 and 100 poses): seed 101 UR10-like 1.026 / 1.028 / 1.037, layer-only
    1.427 / 1.395 / 1.324; seed 102 layer-only 1.254 / 1.235 / 1.247, compliance + gear + drift 1.348 / 1.430 /
    1.386, sparse far 1.443 / 1.421 / 1.418. ``f`` itself ran on no data set; nothing was changed after these runs.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select.py --adaptive --rules d f df
        --seeds 7 8 9 [--forms ... --json A.json] [--combine A.json B.json --rules d f df]

Outcome of the third protocol (run on cfbbaa5; two processes, --combine; the table is in docs/results.md): score
over forms and sizes f 1.156, df 1.206, d 1.300. ``f`` is chosen (11 % below d) and is now ``RULE`` (since moved to ``campaign.plan.adaptive``, beside the seed); under it the
replay's poses are the one-shot selection's. The goals for it: met on the UR5 (1.218 / 1.073); NOT met at 50 poses on
the sparse-far-pose form (1.480) and the layer-only form (1.358), at 100 on the layer-only form (1.261). ``d`` broke
down at 50 poses on seed 8 of the UR10-like form (5.03 x: a registration drift in measurement order taken on its
rows; bench_select_stages.py).

Issue 32, the goals of the rule as it is at twenty fresh seeds (a measurement on the code of 92abd6e, whose last
change to the default was the twentieth protocol; this paragraph is committed before the run, and nothing in the
code changes for it). Three seeds leave the mean ratio of a form within about 0.05 of its expectation, and the
compliance + gear + drift form at 50 poses sits near its goal (1.360 at seeds 97-99; ``bench_goals.py`` before
this: 1.314 se 0.019 over seeds 43-96). So that form alone is measured at seeds 120-139, never run by any bench
before this paragraph (the UR5 campaign and the five other forms meet their goals by more than their spread over
seeds 91-99). Rule ``f``, its seed, the one-shot selection and random subsets as above; two processes (seeds
120-129 and 130-139), then ``--combine``. The goal line of the combined summary is the verdict on the form.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 python3 bench/bench_select.py --adaptive --rules f
        --forms compliance+gear+drift --seeds 120 ... 129 --json A.json   (and 130 ... 139 --json B.json)
    python3 bench/bench_select.py --adaptive --rules f --combine A.json B.json

Outcome (on 6bc9889, as planned): 50 poses 1.317 (worst 1.860), 100 poses 1.107 (worst 1.343); random subsets
1.360 / 1.118. The goal line prints "met" at both sizes. 6 of the 20 seeds are above 1.35 at 50 poses. See
docs/results.md ("Issue 32's goals at fresh seeds 100-139").
"""
from __future__ import annotations

import argparse
import math
from dataclasses import replace
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from campaign.calibrate.effects_stage import effect_choices, effect_meta  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.data.dataset import Dataset  # noqa: E402
from robocal.design.optimal import (_Design, criterion, criterion_effects, d_optimal, design_columns,  # noqa: E402
                            farthest_first, information_rows)
from robocal.layers.joint_gp import prior_columns  # noqa: E402
from robocal.identify.identification import calibrate, register  # noqa: E402
from robocal.kinematics.models import ParamLayout  # noqa: E402
from tests.campaign.helpers import simulated_campaign  # noqa: E402


GEAR = [1.4e-4, 1.4e-4, 7.0e-5, 7.0e-5]
FORMS = {
    "irb2600 compl+gear2": ("irb2600.yaml", [{"name": "joint_compliance", "params": {"values": [1.0e-6, 2.0e-6]}},
                                             {"name": "gear_cyclic", "params": {"joint": 2, "values": GEAR}}]),
    "irb4600 gear3+coupling": ("irb4600.yaml", [{"name": "gear_cyclic", "params": {"joint": 3, "values": GEAR}},
                                                {"name": "axis_coupling", "params": {"values": [3e-4, 2e-4, 2e-4]}}]),
    "ur10 geometry": ("ur10.yaml", []),
    "ur5-sim gear1": ("ur5.yaml", [{"name": "gear_cyclic", "params": {"joint": 1, "values": GEAR}}]),
}
UR5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
N_RANDOM = 5


CURRENT = "kcenter"             # what ``campaign select`` uses (robocal.design.optimal.space_filling)
CRITERIA = ("d_spread", "d_joint", "d", "i", "di", "d_cover", "i_cover", "kcenter", "d_herd", "d_fill", "d_fx")


class _IDesign(_Design):
    """``_Design`` that also keeps trace(H M^-1) and, per candidate, T_i = A_i M^-1 H M^-1 A_i^T (3, 3, M): the
    prediction variance over the pool (H (L, L) the pool's mean prior-scaled J^T J) removed by adding each."""

    def __init__(self, A: np.ndarray, H: np.ndarray) -> None:
        self.H = H
        super().__init__(A)

    def _forms(self, W: np.ndarray) -> np.ndarray:
        B = (W @ self.flatT).reshape(W.shape[0], -1, 3)
        return np.einsum("lmi,mjl->ijm", B, self.A)

    def refresh(self) -> None:
        super().refresh()
        self.T = self._forms(self.Minv @ self.H @ self.Minv)
        self.trace = float(np.sum(self.Minv * self.H))

    def _update(self, k: int, sign: float) -> None:
        U = self.Minv @ self.A[k].T
        C = np.linalg.inv(np.eye(3) + sign * self.S[:, :, k])
        Xt = np.ascontiguousarray((U.T @ self.flatT).reshape(3, -1, 3).transpose(2, 0, 1))
        Yt = np.einsum("ijm,jk->ikm", Xt, C)
        W = self.Minv @ (self.H @ U)
        Zt = np.ascontiguousarray((W.T @ self.flatT).reshape(3, -1, 3).transpose(2, 0, 1))
        Q = U.T @ self.H @ U
        t1 = np.einsum("ikm,jkm->ijm", Yt, Zt)
        self.T += np.einsum("ikm,kl,jlm->ijm", Yt, Q, Yt) - sign * (t1 + t1.transpose(1, 0, 2))
        self.trace -= sign * float(np.sum(C * Q))
        super()._update(k, sign)

    def i_gains(self) -> np.ndarray:
        """trace(H M^-1) removed by adding each candidate (M,): trace((I + S_i)^-1 T_i)."""
        inv = np.linalg.inv(np.eye(3)[None] + self.S.transpose(2, 0, 1))
        return np.einsum("mij,jim->m", inv, self.T)


class _Coverage:
    """The residual layer's share of the prediction error: a zero-mean GP per axis, prior variance ``prior_mm2``,
    squared-exponential kernel of length ``length_mm`` on coordinates X (M, d) mm (joint angle x lever), noise
    (M,) mm^2; keeps every candidate's posterior variance and g_k = sum over the integration rows R of
    cov(x_r, x_k)^2 under rank-one updates."""

    def __init__(self, X: np.ndarray, noise_mm2: np.ndarray, R: np.ndarray, length_mm: float, prior_mm2: float):
        self.X, self.noise, self.R = X, np.asarray(noise_mm2, float), np.asarray(R, int)
        self.length, self.prior = float(length_mm), float(prior_mm2)
        self.K_RM = self._kernel(X[self.R])
        self.g = np.einsum("rm,rm->m", self.K_RM, self.K_RM)
        self.var = np.full(len(X), self.prior)
        self.U = np.zeros((0, len(X)))

    def _kernel(self, Xa: np.ndarray) -> np.ndarray:
        d2 = np.sum(Xa**2, 1)[:, None] + np.sum(self.X**2, 1)[None, :] - 2.0 * Xa @ self.X.T
        return self.prior * np.exp(-np.maximum(d2, 0.0) / (2.0 * self.length**2))

    def gains(self) -> np.ndarray:
        """(M,) mean over R of the posterior variance (3 axes, mm^2) removed by observing each candidate."""
        return 3.0 * np.maximum(self.g, 0.0) / (self.var + self.noise) / len(self.R)

    def add(self, k: int) -> None:
        c = self._kernel(self.X[k: k + 1])[0] - self.U[:, k] @ self.U
        u = c / np.sqrt(c[k] + self.noise[k])
        uR = u[self.R]
        v = uR @ self.K_RM - (self.U[:, self.R] @ uR) @ self.U
        self.g += -2.0 * u * v + u**2 * float(uR @ uR)
        self.var -= u**2
        self.U = np.vstack([self.U, u])


def _farthest_first(X: np.ndarray, n: int) -> np.ndarray:
    """n rows of X (M, d) chosen farthest-first (``robocal.design.optimal.farthest_first``), and the fill distance reached."""
    out = farthest_first(X, n)
    return out, float(np.max(np.min(np.linalg.norm(X[:, None] - X[out][None], axis=2), axis=1)))


def _fill(X: np.ndarray, first: np.ndarray, n: int) -> np.ndarray:
    """``first`` then rows of X (M, d) farthest from every chosen one, up to n."""
    chosen = list(first)
    d = np.min(np.linalg.norm(X[:, None, :] - X[None, chosen, :], axis=2), axis=1)
    while len(chosen) < n:
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(X - X[k], axis=1))
    return np.array(chosen)


def _herding(X: np.ndarray, first: np.ndarray, n: int) -> np.ndarray:
    """``first`` then rows of X (M, d) by kernel herding up to n: each next row the one that brings the chosen set's
    kernel mean closest to the pool's (a representative sample; Gaussian kernel, median-distance bandwidth)."""
    d2 = np.maximum(np.sum(X**2, 1)[:, None] + np.sum(X**2, 1)[None] - 2.0 * X @ X.T, 0.0)
    K = np.exp(-d2 / np.median(d2[np.triu_indices(len(X), 1)]))
    mu, chosen = K.mean(1), list(first)
    taken = np.zeros(len(X), bool)
    taken[chosen] = True
    acc = K[:, chosen].sum(1)
    while len(chosen) < n:
        k = int(np.argmax(np.where(taken, -np.inf, mu - acc / (len(chosen) + 1))))
        chosen.append(k)
        taken[k] = True
        acc += K[:, k]
    return np.array(chosen)


def choose(ctx, n: int, name: str) -> np.ndarray:
    """Candidate indices (n,) by criterion ``name``: d_spread (``campaign select``), d (pure Bayesian D), i (pool
    prediction variance), di (D and I as log-ratios), d_cover / i_cover (plus a GP coverage term), kcenter,
    d_herd (D-spread for 1.2 x the identifiable parameters, then kernel herding: robust to an unmodelled part),
    d_fill (the same, then farthest-first), d_fx (D-spread on the effects the whole data set supports)."""
    crit, H, X, noise, supported, curves = ctx
    if name == "d_spread":
        return d_optimal(crit.A, n, crit.spread).chosen
    if name == "d":
        return d_optimal(crit.A, n).chosen
    if name == "d_joint":             # D-spread with the joint-error GP layer's weights under their design prior
        c = curves()
        return d_optimal(c.A, n, c.spread).chosen
    if name == "kcenter":
        return _farthest_first(X, n)[0]
    if name == "d_fx":                # D-spread on geometry + the effects the whole data set supports
        c = supported()
        return d_optimal(c.A, n, c.spread).chosen
    if name == "d_fill":              # D for identifiability, then farthest-first (space-filling) rows
        first = d_optimal(crit.A, min(n, math.ceil(1.2 * crit.identifiable)), crit.spread).chosen
        return _fill(X, first, n)
    if name == "d_herd":              # a compromise design: D for identifiability, then representative rows
        return _herding(X, d_optimal(crit.A, min(n, math.ceil(1.2 * crit.identifiable)), crit.spread).chosen, n)
    M, L = crit.A.shape[0], crit.A.shape[2]
    d = _IDesign(crit.A, H)
    cov = None
    if name.endswith("cover"):
        R = np.arange(M) if M <= 1000 else np.sort(np.random.default_rng(0).choice(M, 1000, replace=False))
        cov = _Coverage(X, noise, R, _farthest_first(X, n)[1], float(np.mean(noise)))
    taken = np.zeros(M, bool)
    for _ in range(n):
        if name == "i":
            g = d.i_gains()
        elif name == "i_cover":
            g = d.i_gains() + cov.gains()
        elif name == "di":
            g = d.gains() / L - np.log(np.maximum(1.0 - d.i_gains() / d.trace, 1e-300))
        else:                                            # d_cover
            g = d.gains() + 3.0 * np.log1p(cov.var / cov.noise)
        k = int(np.argmax(np.where(taken, -np.inf, g)))
        d.add(k)
        taken[k] = True
        if cov is not None:
            cov.add(k)
    return np.array(d.chosen, int)


METRIC = ["rms_mm"]             # the protocol's score; --metric mean_mm: the same comparison on the mean error


def held_out(ds: Dataset, cell) -> float:
    """Held-out statistic (``METRIC``, mm) of the default calibration of ``ds``."""
    return float(getattr(calibrate_dataset(ds, cell).report.final.test, METRIC[0]))


def crit_of(ds: Dataset, cell):
    """The criterion ``campaign select`` builds on the calibration rows (registered nominal model), the pool's
    H (L, L), the coverage coordinates (M, n) mm and the per-row noise (M,) mm^2."""
    cal = np.flatnonzero(ds.mask("calib"))
    q = np.radians(ds.q_deg[cal])
    kin = register(cell.kinematics, q, ds.p_tracker_mm[cal])
    payload = float(np.mean(ds.payload_kg[cal])) if ds.payload_kg is not None else float(cell.payload_kg or 0.0)
    cov = cell.weights(ds)[0][cal]
    crit = criterion(kin, q, cov, payload)
    J, _, prior = design_columns(kin, q, {"payload_kg": np.full(len(q), payload)}, criterion_effects(kin, q, payload))
    B = J * prior
    theta = [c for c, _, k in ParamLayout.of(kin).joint_cols if k == 0]
    lever = np.sqrt(np.mean(np.sum(J[:, :, theta] ** 2, axis=1), axis=0))       # mm/rad per joint
    supported = lambda: criterion(kin, q, cov, payload, supported_effects(ds, cell))  # noqa: E731
    def curves():                     # with the joint-error GP layer's weights under their design prior
        Jc, names_c, prior_c = prior_columns(kin, q)
        return replace(crit, A=np.concatenate([crit.A, information_rows(Jc, cov, prior_c)], axis=2),
                       names=crit.names + names_c)
    return (crit, np.einsum("nip,niq->pq", B, B) / len(q), q * lever, np.trace(cov, axis1=1, axis2=2) / 3.0,
            supported, curves)


def supported_effects(ds: Dataset, cell) -> list:
    """The pose-dependent effects the effect engine takes on all calibration rows of ``ds`` (around their
    geometric fit): the model this campaign supports, for the ``d_fx`` criterion."""
    cal = np.flatnonzero(ds.mask("calib"))
    q, p = np.radians(ds.q_deg[cal]), ds.p_tracker_mm[cal]
    cov = cell.weights(ds)[0][cal]
    geo = calibrate(cell.kinematics, q, p, cov, cell.options)
    layout = ParamLayout.of(geo.kinematics)
    cols = np.array([layout.index(name) for name in geo.identified])
    choices, _ = effect_choices(cell, geo.kinematics, cols, q, p, cov, effect_meta(ds, cell, cal))
    return [c for c in choices if not c.build(geo.kinematics.n).needs]


def sim_dataset(tmp: Path, name: str, seed: int):
    cfg_name, effects = FORMS[name]
    d = yaml.safe_load((ROOT / "configs" / cfg_name).read_text())
    d.setdefault("simulation", {}).update(seed=seed, effects=effects)
    path = tmp / f"{cfg_name}-{seed}.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    cell = load_cell(path)
    return simulated_campaign(cell, seed), cell


def ur5_dataset(tmp: Path):
    from campaign.data.importers import import_target_dif
    return (import_target_dif(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv",
                              UR5 / "3D_UR5_uncalibrated_random_cleaned.csv"), load_cell(ROOT / "configs/ur5.yaml"))


def ur5_split_datasets(seeds):
    """The UR5 campaign with a large held-out set, one data set per seed: its 1000 grid rows split in seeded halves;
    the calibration rows are one half (the pool, 100 chosen of 500), the test rows the other half plus the 20
    random poses (520 held out, against 20 in ``ur5-real``)."""
    ds, cell = ur5_dataset(None)
    cal = np.flatnonzero(ds.mask("calib"))
    for seed in seeds:
        held = np.random.default_rng(100 + seed).permutation(cal)[len(cal) // 2:]
        sets = np.array(ds.set, dtype=object)
        sets[held] = "test"
        yield seed, replace(ds, set=tuple(sets)), cell, 100


def evaluate(ds: Dataset, cell, n: int | None, criteria) -> dict[str, float]:
    """Held-out RMS ratio to all rows per criterion, plus 'random' (median of N_RANDOM) and 'all' (mm)."""
    cal = np.flatnonzero(ds.mask("calib"))
    ctx = crit_of(ds, cell)
    if n is None:
        n = max(round(len(cal) / 3), math.ceil(1.2 * ctx[0].identifiable))
    everything = held_out(ds, cell)
    out = {"all_mm": everything, "n": n, "M": len(cal)}

    def subset(idx):
        keep = ~ds.mask("calib")
        keep[cal[np.asarray(idx, int)]] = True
        return held_out(ds.with_order_context().subset(keep), cell) / everything   # as select writes it
    for c in criteria:
        out[c] = subset(choose(ctx, n, c))
    out["random"] = float(np.median([subset(np.random.default_rng(s).choice(len(cal), n, replace=False))
                                     for s in range(N_RANDOM)]))
    return out


def main() -> None:
    if "--adaptive" in sys.argv[1:]:                    # issue 32's protocol (docstring)
        sys.path.insert(0, str(ROOT / "bench"))
        from select_replay import main as replay
        return replay(sys.argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--criteria", nargs="+", default=list(CRITERIA))
    ap.add_argument("--forms", nargs="+", default=["ur5-real", *FORMS])
    ap.add_argument("--metric", choices=("rms_mm", "mean_mm"), default="rms_mm",
                    help="held-out statistic compared (the protocol: rms_mm)")
    args = ap.parse_args()
    METRIC[0] = args.metric
    cols = [*args.criteria, "random"]
    table: dict[str, list[dict]] = {}
    print(f"held-out {args.metric} of the chosen subset / that of all rows (default process), per data set")
    print(f"{'form':26s}{'seed':>5s}{'n/M':>10s}{'all mm':>8s}" + "".join(f"{c:>10s}" for c in cols), flush=True)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for form in args.forms:
            runs = [(0, *ur5_dataset(tmp), 100)] if form == "ur5-real" else \
                list(ur5_split_datasets(args.seeds)) if form == "ur5-split" else \
                [(s, *sim_dataset(tmp, form, s), None) for s in args.seeds]
            for seed, ds, cell, n in runs:
                r = evaluate(ds, cell, n, args.criteria)
                table.setdefault(form, []).append(r)
                print(f"{form:26s}{seed:5d}{r['n']:>5d}/{r['M']:<4d}{r['all_mm']:8.4f}"
                      + "".join(f"{r[c]:10.3f}" for c in cols), flush=True)
    print("\nmean ratio per form (over seeds), and over forms")
    means = {f: {c: float(np.mean([r[c] for r in rs])) for c in cols} for f, rs in table.items()}
    for f, m in means.items():
        print(f"{f:26s}{'':23s}" + "".join(f"{m[c]:10.3f}" for c in cols))
    overall = {c: float(np.mean([m[c] for m in means.values()])) for c in cols}
    print(f"{'MEAN OVER FORMS':26s}{'':23s}" + "".join(f"{overall[c]:10.3f}" for c in cols))
    best = min(args.criteria, key=overall.get)
    keep = CURRENT in overall and overall[CURRENT] <= 1.01 * overall[best]
    print(f"best: {best} ({overall[best]:.3f}); chosen by the protocol: {CURRENT if keep else best} "
          f"(current: {CURRENT}, kept unless another is more than 1 % better)")


if __name__ == "__main__":
    main()
