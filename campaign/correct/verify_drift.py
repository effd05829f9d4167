"""Tracker-registration drift during ``campaign verify``: the reference nests of the run's config are read as in
the run (at verify's start, every ``plan.nests.every_n_points`` points, and at the end of every pass, so at
verify's end too), and every measurement is moved into the tracker frame of the calibration (the run's first
reading, the frame its registration refers to) before it is compared with a target or fed to the closed loop. The
drift model is the calibration's own (:func:`campaign.calibrate.prepare.fit_nest_drift`), fitted on the run's and
verify's nest readings together on one clock (a real cell's wall clock; a simulated cell's clock continues from
the run's)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from campaign.calibrate.prepare import fit_nest_drift
from campaign.config.plan_schema import NestsConfig
from campaign.plan.points import PlanPoint
from campaign.plan.poses import with_nest_rounds
from campaign.run.log_records import NestRecord, PointRecord

FRAME = "tracker frame of the calibration (the run's first reading; the drift since then removed)"


class VerifyDrift:
    """The nest rounds of a verification and the drift correction of its measurements. ``run_records``: the
    run's log records (its nest readings anchor the calibration's frame); ``source`` names the run in errors.
    ``passes``: stage -> the drift removed from that pass (mean translation mm and rotation urad over its
    points, tracker frame); ``report``: the last fit's section for verify.json."""

    def __init__(self, nests: NestsConfig, run_records: Sequence, source: str) -> None:
        self.nests, self.source = nests, source
        times = [r.t_end_s for r in run_records if r.t_end_s is not None]
        self.t0_s = times[0] if times else 0.0          # the run's first reading: t = 0 of the calibration's drift
        self.run_nests = [r for r in run_records if isinstance(r, NestRecord) and r.t_end_s is not None]
        self.passes: dict[str, dict] = {}
        self.report: dict | None = None
        self._verify_nests: list[NestRecord] = []
        self._t_pass: list[float] = []                  # times (s) of the current pass's robot readings
        self._rounds = 0

    @property
    def active(self) -> bool:
        """Nests are read (the config has some)."""
        return bool(self.nests.points)

    def with_rounds(self, points: list[PlanPoint], start: bool) -> list[PlanPoint]:
        """A pass's points with rounds of nest readings as in the run (:func:`campaign.plan.poses.with_nest_rounds`):
        after every ``every_n_points`` points and at the end, and (``start``) at the start."""
        out = with_nest_rounds(points, self.nests, self._rounds, start)
        self._rounds += sum(p.set == "nest" for p in out) // max(len(self.nests.points), 1)
        return out

    def observe(self, record: PointRecord | NestRecord) -> None:
        """A record on disk: a nest reading, or a robot point of the current pass (its time)."""
        if isinstance(record, NestRecord):
            self._verify_nests.append(record)
        else:
            self._t_pass.append(record.t_end_s)

    def run_frame(self, points: Sequence[PointRecord], stage: str) -> np.ndarray:
        """The run's readings of ``points`` (N, 3) mm in the calibration's frame (the calibration's own drift
        model: the run's nest readings only)."""
        p = np.array([r.p_tracker_mm for r in points], float)
        return self._correct(stage, p, np.array([r.t_end_s for r in points], float), self.run_nests)

    def pass_frame(self, p_tracker_mm: np.ndarray, stage: str) -> np.ndarray:
        """The pass just measured, readings (N, 3) mm, in the calibration's frame (the run's and verify's nest
        readings so far, the round after the pass included)."""
        t = np.array(self._t_pass[len(self._t_pass) - len(p_tracker_mm):], float)
        self._t_pass = []
        return self._correct(stage, p_tracker_mm, t, self.run_nests + self._verify_nests)

    def _correct(self, stage: str, p: np.ndarray, t_s: np.ndarray, nests: list[NestRecord]) -> np.ndarray:
        if not self.active:
            return p
        if not self.run_nests:
            self.report = {"applied": False, "frame": FRAME,
                           "why": "the run has no nest readings: no calibration frame to refer the drift to"}
            return p
        t = np.array([r.t_end_s for r in nests]) - self.t0_s
        model, report = fit_nest_drift(self.source, t, np.array([r.nest_id for r in nests]),
                                       np.array([r.p_tracker_mm for r in nests], float),
                                       np.array([r.point_id for r in nests]), float(t.max()))
        self.report = report | {"frame": FRAME, "readings_run": len(self.run_nests),
                                "readings_verify": len(nests) - len(self.run_nests)}
        if model.degree == 0 or not len(p):
            self.passes[stage] = {"translation_mm": [0.0] * 3, "rotation_urad": [0.0] * 3}
            return p
        tr = t_s - self.t0_s
        self.passes[stage] = {"translation_mm": model.translation_mm(tr).mean(axis=0).tolist(),
                              "rotation_urad": (1e6 * model.rotation_rad(tr)).mean(axis=0).tolist()}
        return model.correct(p, tr)

    def section(self) -> dict | None:
        """verify.json's ``drift`` section: the last fit and the drift removed from each pass (None without
        nests)."""
        if not self.active or self.report is None:
            return None
        return self.report | {"passes": dict(self.passes)}
