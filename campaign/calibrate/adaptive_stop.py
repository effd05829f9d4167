"""``plan.stop: auto``: measure an optimal plan block by block and stop when the next block would not pay.

After every block (``Plan.blocks``) the calibration points measured so far (read back from the durable log) are
refitted: geometry by Levenberg-Marquardt, the effects ``calibration.effects`` takes, linearised at that
solution. ``robocal.design.optimal.prediction`` turns the fit into the held-out RMS expected of the model fitted on the
first n planned points, for every block end n: noise floor at the test poses + the part the model cannot fit
(blocked cross-validation of the data so far) + the parameter uncertainty of exactly those planned poses. The run
stops when the next block is predicted to lower it by less than ``plan.stop_gain_pct`` % of the floor, or when
``plan.max_minutes`` would be exceeded; then the test set (the plan's points after its last calibration point) is
measured. Each decision is a ``stop_check`` event in the log, so a resumed run continues where it was: measuring
blocks, or (after a stop) the test set only.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ClassVar, Sequence

import numpy as np

from robocal.measure.approach import approach_signs
from robocal.design.optimal import prediction, whiten_rows
from robocal.effects.bases import effect_regressor
from robocal.identify.identification import IdentificationError, calibrate
from robocal.kinematics.models import ParamLayout, identification_jacobian, smr_tracker

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.data.log_dataset import dataset_from_log
from campaign.io.quantities import floor_mm
from campaign.plan.points import Plan, PlanPoint
from campaign.errors import one_line
from campaign.run.log_events import LogEvent
from campaign.run.log_reader import LogContents, read_log

from .report_sections import StopSummary

logger = logging.getLogger(__name__)
STOP_EVENT = "stop_check"
ROUND_EVENT = "adaptive_round"          # plan.kind: adaptive (campaign.calibrate.adaptive_rounds)


@dataclass(frozen=True)
class StopCheck(LogEvent):
    """One refit after a block: predicted held-out RMS (mm) now and at every block end (``curve``), the gain of
    the next block, the threshold, the fit's figures and the decision (continue | stop) with its reason. A
    ``stop_check`` event of the log (a prediction not yet possible is inf here; the log stores it as null, read
    back as None)."""
    TYPE: ClassVar[str] = STOP_EVENT
    n_calib: int
    predicted_rms_mm: float | None
    gain_next_mm: float | None
    threshold_mm: float
    floor_mm: float | None
    unmodelled_mm: float | None
    cv_rms_mm: float | None
    s0: float | None
    curve: tuple[tuple[int, float], ...]
    elapsed_min: float
    decision: str
    reason: str


@dataclass(frozen=True)
class RefitFailed(LogEvent):
    """A ``stop_check`` whose refit failed: the run keeps measuring as planned (``decision`` continue)."""
    TYPE: ClassVar[str] = STOP_EVENT
    n_calib: int
    decision: str
    reason: str


def stop_checks(contents: LogContents | None) -> list[dict]:
    """The ``stop_check`` events of a log (``adaptive_round`` events of an adaptive run), in order."""
    return [e for e in (getattr(contents, "events", None) or []) if e.get("type") in (STOP_EVENT, ROUND_EVENT)]


def _rows(kin, q, meta, effects, p_J=None):
    """Columns (N, 3, P) mm: identified geometric columns and the effect regressors at q (N, n) rad."""
    p, J = identification_jacobian(kin, q) if p_J is None else p_J
    cols, eff = effects
    regs = [effect_regressor(kin, q, meta, e, jacobian=(p, J)) for e in eff]
    return np.concatenate([J[:, :, cols]] + regs, axis=2)


def _plan_meta(cell: CellModel, q_deg: np.ndarray, t_done: np.ndarray | None) -> dict:
    """Effect metadata of planned poses (N, n) deg in plan order: payload, approach signs of the planned sequence,
    times (measured ones, then extrapolated at the mean rate so far)."""
    n = len(q_deg)
    t = None
    if t_done is not None and len(t_done) > 1:
        rate = (t_done[-1] - t_done[0]) / (len(t_done) - 1)
        t = np.concatenate([t_done, t_done[-1] + rate * np.arange(1, n - len(t_done) + 1)])[:n]
    return {"payload_kg": np.full(n, cell.payload_kg), "approach": approach_signs(q_deg), "t_s": t}


def evaluate(cell: CellModel, plan: Plan, contents: LogContents, elapsed_s: float) -> StopCheck:
    """Refit the calibration points of the log ``contents`` and decide whether the next block is worth it."""
    from .effects_stage import effect_choices, effect_meta   # the calibration numerics load when a block ends
    ds = dataset_from_log(contents)
    cal = np.flatnonzero(ds.mask("calib"))
    q, p = np.radians(ds.q_deg[cal]), ds.p_tracker_mm[cal]
    cov = cell.weights(ds)[0][cal]
    geo = calibrate(cell.kinematics, q, p, cov, cell.options)
    kin = geo.kinematics
    cols = np.array([ParamLayout.of(kin).index(nm) for nm in geo.identified])
    meta = effect_meta(ds, cell, cal)
    choices, _ = effect_choices(cell, kin, cols, q, p, cov, meta)
    effects = (cols, [c.build(kin.n) for c in choices])
    p_J = identification_jacobian(kin, q)
    J = _rows(kin, q, meta, effects, p_J)
    r0 = p - p_J[0]
    Gw, rw0 = whiten_rows(J, cov), whiten_rows(r0[:, :, None], cov)[:, :, 0]
    P = J.shape[2]
    x = np.linalg.lstsq(Gw.reshape(-1, P), rw0.reshape(-1), rcond=1e-10)[0]
    r = r0 - J @ x
    planned = [pt for pt in plan.points if pt.set == "calib"]
    q_plan_deg = np.array([pt.q_deg for pt in planned])
    q_plan = np.radians(q_plan_deg)
    J_plan = _rows(kin, q_plan, _plan_meta(cell, q_plan_deg, meta.get("t_s")), effects)
    G_plan = whiten_rows(J_plan, cell.covariance(smr_tracker(kin, q_plan)))
    q_test = np.radians([pt.q_deg for pt in plan.points if pt.set == "test"]).reshape(-1, kin.n)
    if not len(q_test):                                    # no test set: judge at the planned poses
        q_test = q_plan
    J_test = _rows(kin, q_test, _plan_meta(cell, np.degrees(q_test), None), effects)
    pred = prediction(G_plan, len(cal), np.array(plan.blocks), Gw, whiten_rows(r[:, :, None], cov)[:, :, 0], J, r,
                      cov, J_test, cell.covariance(smr_tracker(kin, q_test)))
    return _decide(cell.config, plan, len(cal), pred, elapsed_s)


def _decide(cfg: CampaignConfig, plan: Plan, n: int, pred, elapsed_s: float) -> StopCheck:
    pl = cfg.plan
    b = plan.blocks.index(n) if n in plan.blocks else int(np.searchsorted(plan.blocks, n))
    now = float(pred.rms_mm[min(b, len(plan.blocks) - 1)])
    nxt = float(pred.rms_mm[b + 1]) if b + 1 < len(plan.blocks) else None
    gain = None if nxt is None else now - nxt
    threshold = pl.stop_gain_pct / 100.0 * pred.floor_mm
    elapsed_min = elapsed_s / 60.0
    per_point_min = elapsed_min / max(n, 1)
    next_block = (plan.blocks[b + 1] - n) if b + 1 < len(plan.blocks) else 0
    if nxt is None:
        decision, why = "stop", f"all {n} planned calibration points measured"
    elif pl.max_minutes is not None and elapsed_min + per_point_min * next_block > pl.max_minutes:
        decision, why = "stop", (f"max_minutes budget: {elapsed_min:.0f} of {pl.max_minutes:g} min used, the next "
                                 f"block needs about {per_point_min * next_block:.0f}")
    elif not np.isfinite(now) or not np.isfinite(gain):
        decision, why = "continue", "too few points for a prediction yet"
    elif gain < threshold:
        decision, why = "stop", (f"the next block would lower the predicted held-out RMS by {gain * 1000:.2f} um, "
                                 f"less than {pl.stop_gain_pct:g} % of the noise floor ({threshold * 1000:.2f} um)")
    else:
        decision, why = "continue", f"the next block is predicted to gain {gain * 1000:.2f} um"
    curve = tuple((int(k), float(v)) for k, v in zip(pred.n_points, pred.rms_mm) if np.isfinite(v))
    return StopCheck(n, now, gain, threshold, pred.floor_mm, pred.unmodelled_mm, pred.cv_rms_mm, pred.s0, curve,
                     elapsed_min, decision, why)


class AdaptivePasses:
    """The passes of a ``stop: auto`` run (``campaign.run.runner.PassPlan``): the pending points of one block at a
    time, a refit and a ``stop_check`` event after each block, then the points after the last calibration point
    (test set, final check and nest rounds)."""

    def __init__(self, cell: CellModel, plan: Plan, run_dir: Path, log, done_ids: set[str],
                 on_skip: Callable[[int], None] | None = None) -> None:
        self.cell, self.plan, self.run_dir, self.log = cell, plan, Path(run_dir), log
        self.done = set(done_ids)
        self.on_skip = on_skip
        calib = [i for i, pt in enumerate(plan.points) if pt.set == "calib"]
        ends = [calib[n - 1] + 1 for n in plan.blocks]
        self.segments = list(zip([0] + ends[:-1], ends))
        self.tail = (ends[-1] if ends else 0, len(plan.points))
        self.current: int | None = None
        checks = stop_checks(read_log(run_dir))
        self.checked = {c["n_calib"] for c in checks}
        self.stopped = any(c.get("decision") == "stop" for c in checks)

    def _pending(self, span: tuple[int, int]) -> list[PlanPoint]:
        return [pt for pt in self.plan.points[span[0]: span[1]] if pt.point_id not in self.done]

    def first(self) -> Sequence[PlanPoint] | None:
        return self._from(0)

    def next(self, p_tracker_mm) -> Sequence[PlanPoint] | None:
        if self.current is None:                         # the tail was measured
            return None
        b = self.current
        if self._check(b):
            return self._to_tail(b)
        return self._from(b + 1)

    def _from(self, b: int) -> Sequence[PlanPoint] | None:
        """The first block from ``b`` on with pending points (checking finished blocks on the way), else the tail."""
        while not self.stopped and b < len(self.segments):
            todo = self._pending(self.segments[b])
            if todo:
                self.current = b
                return todo
            if self._check(b):
                return self._to_tail(b)
            b += 1
        return self._to_tail(len(self.segments) - 1)

    def _check(self, b: int) -> bool:
        """Refit after block b (once): True when the run should stop there."""
        n = self.plan.blocks[b]
        if b == len(self.segments) - 1:
            return True
        if n in self.checked:
            return False
        contents = read_log(self.run_dir)
        # robot time: the sum of the points' own durations (a pause or a resume between sessions does not count)
        elapsed = sum(max(0.0, float(r.t_end_s - r.t_start_s)) for r in contents.records())
        try:
            check = evaluate(self.cell, self.plan, contents, elapsed)
        except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:   # keep measuring as planned
            self.log.append_event(RefitFailed(n, "continue", f"refit failed: {one_line(exc)}"))
            self.checked.add(n)
            return False
        self.log.append_event(check)
        self.checked.add(n)
        logger.info("stop check after %d calibration points: predicted held-out RMS %.4f mm (floor %s mm); %s: %s",
                    n, check.predicted_rms_mm, floor_mm(check.floor_mm), check.decision, check.reason)
        self.stopped = check.decision == "stop"
        return self.stopped

    def _to_tail(self, b: int) -> Sequence[PlanPoint] | None:
        """The points after the last calibration point; the skipped blocks are reported to ``on_skip``."""
        self.stopped = True
        skipped = sum(len(self._pending(s)) for s in self.segments[b + 1:])
        if skipped and self.on_skip is not None:
            self.on_skip(skipped)
        self.current = None
        todo = self._pending(self.tail)
        return todo or None


def stop_summary(contents: LogContents, measured_rms_mm: float | None) -> StopSummary | None:
    """``report.json``'s ``stop``: every refit of a ``stop: auto`` run that gave a prediction (predicted curve,
    decision) and, beside the prediction at the stop, the held-out RMS the final model reached on the test set."""
    checks = [c for c in stop_checks(contents) if c.get("predicted_rms_mm") is not None]
    if not checks:
        return None
    last = checks[-1]
    what = "round; choose the next batch with the refitted model" if last["type"] == ROUND_EVENT else "block"
    return StopSummary(f"refit after every {what}; stop when the next "
                       f"{'batch' if last['type'] == ROUND_EVENT else 'block'} is predicted to lower the held-out RMS "
                       "by less than plan.stop_gain_pct % of the noise floor, or at plan.max_points / plan.max_minutes",
                       tuple(checks), last["n_calib"], last["predicted_rms_mm"], measured_rms_mm, last["reason"])


def stopped_after(run_dir: Path) -> int | None:
    """Calibration points after which a ``stop: auto`` run stopped (None: it did not stop early, or no log)."""
    try:
        checks = stop_checks(read_log(run_dir))
    except (OSError, ValueError):
        return None
    return next((int(c["n_calib"]) for c in checks if c.get("decision") == "stop"), None)
