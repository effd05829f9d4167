"""``plan.kind: adaptive``: measure the seed, then round after round a batch, until the refitted model says stop.

After the seed and after every batch the calibration points measured so far (read back from the durable log, with
the check and nest rows; the test set is measured last) are calibrated as ``reprocess`` does
(``adaptive_model.refit``). The next ``plan.block_points`` poses are chosen among the plan's candidates (at most
``MAX_CANDIDATES`` per round, a seeded sample of the pool) by rule ``campaign.plan.adaptive.RULE`` of
``robocal.design.adaptive``, chosen by held-out prediction: ``f``, each the candidate farthest, in joint space
scaled by the levers, from every pose measured or picked (the rules that follow the model's own uncertainty, ``d``
and ``i``, did worse held out); with ``plan.task``, each the candidate nearest the task pose farthest from every
pose measured or picked (``campaign.plan.adaptive.covered_task``). The refitted model judges the batch: predicted
held-out RMS now, the larger of its k-fold CV figure and the noise floor with its own prediction variance at the
task poses; after the batch, that less the variance the batch removes. The rounds stop (``plan.stop: auto``) when
the next batch would lower it by less than ``plan.stop_gain_pct`` % of the noise floor, when the next batch would
exceed ``plan.max_minutes`` of robot time, or at ``plan.max_points``; then the test set is measured. Every decision
is an ``adaptive_round`` event in the log, written before its batch moves the robot (its poses by id, in measurement
order), so a resumed run measures the rest of the batch it was in, then refits; nothing is measured twice and
nothing is lost. Every move is routed by the plan's swept-path guard (via poses; a candidate no route reaches is
left out of the round and named).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, ClassVar, Sequence

import numpy as np

from robocal.design import Coverage, choose_batch, lever_scaled, short_tour
from robocal.identify.identification import IdentificationError
from robocal.kinematics.models import smr_tracker

from campaign.config.cell_model import CellModel
from campaign.data.log_dataset import dataset_from_log
from campaign.errors import DataError, one_line
from campaign.io.quantities import floor_mm
from campaign.plan.adaptive import RULE, covered_task, task_poses
from campaign.plan.motion_safety import PathGuard, UnsafeMotion
from campaign.plan.optimal import tracker_kinematics
from campaign.plan.points import Plan, PlanPoint
from campaign.run.log_events import LogEvent
from campaign.run.log_reader import LogContents, read_log

from .adaptive_model import design_terms, predicted_curve, refit, task_sample
from .adaptive_stop import ROUND_EVENT

logger = logging.getLogger(__name__)
MAX_CANDIDATES = 3000           # candidates judged per round (a seeded sample of a larger pool)


@dataclass(frozen=True)
class RoundCheck(LogEvent):
    """One refit: calibration points measured, the layer chosen, predicted held-out RMS now and after each point of
    the next batch (``curve``: (n, mm)), its gain, the threshold, floor and CV figure (mm), robot minutes so far,
    the decision (continue | stop), why, and the batch (point ids in measurement order; empty on a stop). An
    ``adaptive_round`` event of the log (``to_dict``/``from_dict``)."""
    TYPE: ClassVar[str] = ROUND_EVENT
    n_calib: int
    layer: str
    predicted_rms_mm: float | None
    gain_next_mm: float | None
    threshold_mm: float
    floor_mm: float | None
    cv_rms_mm: float | None
    curve: tuple[tuple[int, float], ...]
    elapsed_min: float
    decision: str
    reason: str
    added: tuple[str, ...] = field(default=())


def round_checks(contents: LogContents | None) -> list[RoundCheck]:
    """The ``adaptive_round`` events of a log, in order, as records."""
    return [RoundCheck.from_dict(e) for e in (getattr(contents, "events", None) or []) if e.get("type") == ROUND_EVENT]


def decide_round(cell: CellModel, plan: Plan, contents: LogContents, elapsed_s: float,
                 excluded: frozenset[str] = frozenset(), *, force: bool = False) -> RoundCheck:
    """Refit the calibration points of the log and choose the next batch (or stop), see the module docstring;
    ``force``: failed plausibility checks of the refit are overridden (``--force``)."""
    pl = cell.config.plan
    ds = dataset_from_log(contents)
    n = int(ds.mask("calib").sum())
    elapsed_min = elapsed_s / 60.0
    k = min(pl.block_points, pl.max_points - n)
    stop = lambda why, **kw: RoundCheck(n, kw.get("layer", "-"), kw.get("now"), kw.get("gain"),  # noqa: E731
                                        kw.get("threshold", 0.0), kw.get("floor"), kw.get("cv"), kw.get("curve", ()),
                                        elapsed_min, "stop", why)
    if k <= 0:
        return stop(f"pose budget reached: {n} calibration points (plan.max_points {pl.max_points})")
    per_point = elapsed_min / max(n, 1)
    if pl.max_minutes is not None and elapsed_min + per_point * k > pl.max_minutes:
        return stop(f"max_minutes budget: {elapsed_min:.0f} of {pl.max_minutes:g} min used, the next batch needs "
                    f"about {per_point * k:.0f}")
    cur = refit(ds.subset(~ds.mask("test")), cell, force=force)
    measured = set(np.array(ds.point_id)[ds.mask("calib")])
    pool = [p for p in plan.candidates if p.point_id not in measured and p.point_id not in excluded]
    if len(pool) > MAX_CANDIDATES:
        pick = np.sort(np.random.default_rng(n).choice(len(pool), MAX_CANDIDATES, replace=False))
        pool = [pool[i] for i in pick]
    q = np.radians([p.q_deg for p in pool])
    every = np.radians([p.q_deg for p in plan.candidates])
    task = task_poses(cell, every, np.array([p.p_base_mm for p in plan.candidates]))
    q_task = task[task_sample(len(task))]
    meta = lambda m: {"payload_kg": np.full(m, cell.payload_kg)}  # noqa: E731
    terms = design_terms(cur, q, meta(len(q)), cell.covariance(smr_tracker(cur.kinematics, q)), q_task,
                         meta(len(q_task)))
    kin_t, cover = tracker_kinematics(cell), covered_task(cell, task)
    X = lever_scaled(kin_t, np.vstack([q, np.radians(ds.q_deg[ds.mask("calib")])]), every)
    X_task = None if cover is None else lever_scaled(kin_t, cover, every)
    b = choose_batch(terms, k, np.ones(len(q), bool), RULE, Coverage(X[:len(q)], X[len(q):], X_task))
    floor = cur.floor_mm
    curve = predicted_curve(cur, b, n)
    now, gain = curve[0][1], curve[0][1] - curve[-1][1]
    threshold = pl.stop_gain_pct / 100.0 * floor
    kw = dict(layer=cur.layer_kind, now=now, gain=gain, threshold=threshold if pl.stop == "auto" else 0.0,
              floor=floor, cv=cur.cv_rms_mm, curve=curve)
    if pl.stop == "auto" and gain < threshold:
        return stop(f"the next {k} points would lower the predicted held-out RMS by {gain * 1000:.2f} um, less than "
                    f"{pl.stop_gain_pct:g} % of the noise floor ({threshold * 1000:.2f} um)", **kw)
    order = b.chosen[short_tour(q[b.chosen], np.radians(ds.q_deg[-1]) if len(ds) else None)]
    return RoundCheck(n, cur.layer_kind, now, gain, kw["threshold"], floor, cur.cv_rms_mm, curve, elapsed_min,
                      "continue", f"the next {k} points are predicted to gain {gain * 1000:.2f} um",
                      tuple(pool[i].point_id for i in order))


class AdaptiveRounds:
    """The passes of an adaptive run (``campaign.run.runner.PassPlan``): the seed, then one batch per round (a
    refit and an ``adaptive_round`` event before each), then the points after the seed (test set, final check and
    nest rounds). ``on_skip(n)`` hears of budget points that will not be measured; ``force`` (``--force``) reaches
    every refit."""

    def __init__(self, cell: CellModel, plan: Plan, run_dir: Path, log, done_ids: set[str],
                 on_skip: Callable[[int], None] | None = None, *, force: bool = False) -> None:
        self.cell, self.plan, self.run_dir, self.log, self.force = cell, plan, Path(run_dir), log, force
        self.done = set(done_ids)
        self.on_skip = on_skip
        self.by_id = plan.known_points()
        calib = [i for i, pt in enumerate(plan.points) if pt.set == "calib"]
        self.seed = list(plan.points[: calib[-1] + 1]) if calib else []
        self.tail = list(plan.points[len(self.seed):])
        contents = read_log(run_dir)
        self.done |= {r.point_id for r in contents.records()}      # a resumed run: the batches' points too
        checks = round_checks(contents)
        self.batches = [c.added for c in checks if c.decision == "continue"]
        self.stopped = any(c.decision == "stop" for c in checks)
        self.excluded: set[str] = set()
        self.guard = PathGuard.for_cell(cell)
        self.q_last: np.ndarray | None = None
        self.given: list[PlanPoint] = []
        self.finished = False

    def first(self) -> Sequence[PlanPoint] | None:
        return self._give(self._pending(self.seed)) or self.next(None)

    def next(self, p_tracker_mm) -> Sequence[PlanPoint] | None:
        self.done |= {p.point_id for p in self.given}     # the runner measured the last pass
        self.given = []
        if self.finished:
            return None
        for batch in self.batches:                       # a batch decided before (this session or the last)
            todo = self._pending([self.by_id[i] for i in batch])
            if todo:
                return self._give(self._routed(todo))
        while not self.stopped:
            batch = self._round()
            if batch:
                return self._give(batch)
        self.finished = True
        return self._give(self._pending(self.tail)) or None

    def _give(self, points: list[PlanPoint]) -> list[PlanPoint]:
        self.given = list(points)
        return self.given

    def _pending(self, points) -> list[PlanPoint]:
        return [p for p in points if p.point_id not in self.done]

    def _round(self) -> list[PlanPoint] | None:
        """Refit, log the decision, and return the routed batch (None: stopped, or nothing routable)."""
        contents = read_log(self.run_dir)
        records = [r for r in contents.records() if r.set != "nest"]
        self.done |= {r.point_id for r in contents.records()}
        if records:
            self.q_last = np.asarray(records[-1].q_cmd_deg, float)     # where the robot stands
        elapsed = sum(max(0.0, float(r.t_end_s - r.t_start_s)) for r in contents.records())
        try:
            check = decide_round(self.cell, self.plan, contents, elapsed, frozenset(self.excluded), force=self.force)
        except (DataError, IdentificationError, np.linalg.LinAlgError, ValueError) as exc:
            n = int(sum(r.set == "calib" for r in contents.records()))
            check = RoundCheck(n, "-", None, None, 0.0, None, None, (), elapsed / 60.0, "stop",
                               f"refit failed ({one_line(exc)[:160]}): the rounds stop here")
        points = self._routed([self.by_id[i] for i in check.added])
        if check.decision == "continue" and not points:
            check = replace(check, decision="stop", added=(), reason="no chosen candidate can be reached by a safe path")
        elif len(points) < len(check.added):
            check = replace(check, added=tuple(p.point_id for p in points))
        self.log.append_event(check)          # durable before the batch moves the robot
        logger.info("adaptive round after %d calibration points: layer %s, predicted held-out RMS %s mm (floor %s "
                    "mm); %s: %s", check.n_calib, check.layer, _mm(check.predicted_rms_mm), floor_mm(check.floor_mm),
                    check.decision, check.reason)
        if check.decision == "stop":
            self.stopped = True
            if self.on_skip is not None:
                self.on_skip(max(0, self.cell.config.plan.max_points - check.n_calib))
            return None
        self.batches.append(check.added)
        return points

    def _routed(self, points: list[PlanPoint]) -> list[PlanPoint]:
        """The points with via poses where the swept path from the previous one is blocked; a point no route reaches
        is left out (and not offered again)."""
        if self.guard is None:
            return points
        out, prev = [], self.q_last
        for p in points:
            try:
                vias = () if prev is None else tuple(self.guard.route(prev, p.q_deg))
            except UnsafeMotion as exc:
                logger.warning("candidate %s left out: %s", p.point_id, exc)
                self.excluded.add(p.point_id)
                continue
            out.append(PlanPoint(p.point_id, p.set, p.q_deg, p.p_base_mm, vias))
            prev = np.asarray(p.q_deg, float)
        self.q_last = prev
        return out


def _mm(v: float | None) -> str:
    return "-" if v is None else f"{v:.4f}"
