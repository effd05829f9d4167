"""``campaign select --adaptive``: the adaptive campaign replayed on a campaign already measured.

The same loop as ``plan.kind: adaptive``, with the measured calibration rows as the candidates: the plan's seed
(``campaign.plan.adaptive.seed_rows``: space-filling, the identifiable geometric parameters + 10 %, at least the rows
the layer's cross-validation needs), then batches. Before each batch the rows chosen so far, and only they (with the check and
nest rows; never a test row), are calibrated as ``reprocess`` does (``adaptive_model.refit``), and the batch is
chosen by a rule of ``robocal.design.adaptive``: ``f``, the default (chosen by ``bench/bench_select.py --adaptive``),
the rows farthest in lever-scaled joint space from every row chosen; ``d``, where that model learns most about its
parameters and its layer; ``df``, the two in turn; ``i``, where its predicted error at the task poses falls most.
The task poses (the calibration rows, i.e. the measured box, or ``task_q_rad``) weigh the predicted held-out RMS
of every round, and the choice under rule ``i``. Each kept row carries how the robot reached it in the full campaign, as ``campaign select`` writes
it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.design.adaptive import Coverage, choose_batch
from robocal.design.optimal import criterion
from robocal.identify.identification import IdentificationError
from robocal.kinematics.models import smr_base, smr_tracker

from campaign.config.cell_model import CellModel
from campaign.data.dataset import Dataset
from campaign.errors import DataError, one_line
from campaign.plan.adaptive import RULE, SEED_DESIGN, SEED_SIZE, covered_task, seed_rows, seed_size, task_poses
from campaign.plan.optimal import pose_covariance, tracker_kinematics

from .adaptive_model import design_terms, predicted_curve, refit, task_sample
from .effects_stage import effect_meta
from .plausibility import check_dataset

BATCH = 10
ADAPTIVE = "adaptive: farthest-first rounds, each judged by the refitted model's predicted error at the task poses"


@dataclass(frozen=True)
class Round:
    """One batch: calibration rows measured before it, the layer the refit chose, the held-out RMS its k-fold CV
    gives (mm), the RMS predicted after the batch (mm; CV^2 less the variance the batch removes at the task poses),
    the point ids added, and a note when the refit failed (the batch is then the farthest rows)."""
    n_before: int
    layer: str
    cv_rms_mm: float | None
    predicted_rms_mm: float | None
    added: tuple[str, ...]
    note: str = ""


@dataclass(frozen=True, eq=False)
class AdaptiveSelection:
    """``keep`` (N,) bool: the chosen calibration rows and every other row; ``order`` the chosen rows (indices
    into the dataset) in the order chosen (every prefix is the selection at that size); the seed size and rounds."""
    keep: np.ndarray
    order: np.ndarray
    n_seed: int
    rounds: tuple[Round, ...]
    n_calib: int
    criterion: str = ADAPTIVE


def adaptive_selection(ds: Dataset, cell: CellModel, n: int, *, force: bool = False) -> AdaptiveSelection:
    """``campaign select --adaptive``: ``adaptive_rows`` judged at the config's ``plan.task`` when it has one, its
    picks covering the task (``campaign.plan.adaptive.covered_task``)."""
    if cell.config.plan.task is None:
        return adaptive_rows(ds, cell, n, force=force)
    cal = ds.mask("calib") & np.all(np.isfinite(ds.q_deg), axis=1)
    q = np.radians(ds.q_deg[cal])
    task = task_poses(cell, q, smr_base(cell.kinematics, q))
    return adaptive_rows(ds, cell, n, task_q_rad=task, force=force, cover_task=covered_task(cell, task) is not None)


def adaptive_rows(ds: Dataset, cell: CellModel, n: int, batch: int = BATCH, rule: str = RULE,
                  task_q_rad: np.ndarray | None = None, *, force: bool = False, seed_design: str = SEED_DESIGN,
                  seed_points: str = SEED_SIZE, cover_task: bool = False) -> AdaptiveSelection:
    """The adaptive replay choosing ``n`` calibration rows of ``ds`` (see the module docstring; the seed by
    ``campaign.plan.adaptive.seed_rows`` / ``seed_size``); DataError as for ``select_rows``; ``force`` overrides
    failed plausibility checks (here and in every refit). ``cover_task``: rule ``f``'s picks cover ``task_q_rad``
    instead of every row (``adaptive_selection`` sets it when the config has ``plan.task``)."""
    check_dataset(ds, cell, force=force)
    cal = np.flatnonzero(ds.mask("calib") & np.all(np.isfinite(ds.q_deg), axis=1))
    if len(cal) < n:
        raise DataError(ds.source, f"has {len(cal)} calibration rows, fewer than the {n} requested (--points)")
    ordered = ds.with_order_context()                     # a subset keeps how the robot reached each pose
    q = np.radians(ds.q_deg[cal])
    kin_t = tracker_kinematics(cell)                      # as a plan sees the poses: no measurement used
    payload = float(np.mean(ds.payload_kg[cal])) if ds.payload_kg is not None else cell.payload_kg
    crit = criterion(kin_t, q, pose_covariance(cell, kin_t, q), payload)
    need = math.ceil(1.1 * crit.identifiable_geometric)
    if n < need:
        raise DataError(ds.source, f"--points {n} cannot identify the {crit.identifiable_geometric} geometric "
                                   f"parameters these rows determine: at least {need} (identifiable + 10 %)")
    n0 = seed_size(crit.identifiable_geometric, n, cell.config.calibration.cv_folds, seed_points)
    chosen = [int(i) for i in seed_rows(kin_t, crit, q, n0, seed_design)]
    meta = effect_meta(ordered, cell, cal)
    task = q if task_q_rad is None else np.atleast_2d(task_q_rad)
    q_task = task[task_sample(len(task))]
    others = ~ds.mask("calib") & ~ds.mask("test")          # check and nest rows: measured in any campaign
    rounds = []
    while len(chosen) < n:
        k = min(batch, n - len(chosen))
        taken = np.zeros(len(cal), bool)
        taken[chosen] = True
        keep = others.copy()
        keep[cal[chosen]] = True
        try:
            cur = refit(ordered.subset(keep), cell, force=force)
            cov = cell.covariance(smr_tracker(cur.kinematics, q))       # where the refit predicts the SMR
            X = q * crit.levers_mm_per_rad
            X_task = task * crit.levers_mm_per_rad if cover_task and task_q_rad is not None else None
            b = choose_batch(design_terms(cur, q, meta, cov, q_task), k, ~taken, rule, Coverage(X, X[taken], X_task))
            rounds.append(Round(len(chosen), cur.layer_kind, cur.cv_rms_mm, predicted_curve(cur, b, 0)[-1][1],
                                tuple(ds.point_id[cal[i]] for i in b.chosen)))
            chosen += [int(i) for i in b.chosen]
        except (DataError, IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
            add = _farthest(q * crit.levers_mm_per_rad, taken, k)
            rounds.append(Round(len(chosen), "none", None, None, tuple(ds.point_id[cal[i]] for i in add),
                                f"refit failed ({one_line(exc)[:120]}): the farthest rows instead"))
            chosen += [int(i) for i in add]
    keep = ~ds.mask("calib")
    keep[cal[chosen]] = True
    return AdaptiveSelection(keep, cal[np.array(chosen, int)], n0, tuple(rounds), len(cal))


def _farthest(X: np.ndarray, taken: np.ndarray, k: int) -> list[int]:
    """k rows of X (M, d) not yet ``taken`` (M,) bool, each the farthest from every row taken before it."""
    return [int(i) for i in choose_batch([], k, ~taken, "f", Coverage(X, X[taken])).chosen]
