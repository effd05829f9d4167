"""The whole campaign in one place: config -> plan -> drivers -> durable log -> calibration -> report."""
from __future__ import annotations

import hashlib
import logging
from contextlib import ExitStack
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from drivers.base import SystemClock

from .cell import device_measurement_covariance, measurement_covariance, nominal_kinematics
from .devices import open_cell
from .config import CampaignConfig
from .errors import CampaignError, ConfigError
from .fsutil import atomic_write
from .interchange import read_csv, write_csv
from .log_dataset import dataset_from_log
from .plan import Plan, build_plan, plan_csv_text
from .html_report import report_targets, write_report
from .records import PointRecord
from .outputs import RUN, Claim, check_dir, source_key
from .resume_checks import check_resume, check_unchanged
from .runlog import RunLog, completed_point_ids, read_log
from .runner import RunOutcome, Runner, closing_on_error, pending, start_record
from .eta import RunEta, point_times_s
from .motion_safety import PathGuard, motion_limits, payload
from .terminal import stdout_console
from .tracker_quality import SmrPredictor
from .plausibility import is_forced
from .traceability import check_identity, device_identity, identification, identity_changes, run_logging

if TYPE_CHECKING:
    from .process import Processed


logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunResult:
    run_dir: Path
    outcome: RunOutcome
    processed: Processed | None
    iso9283: dict | None = None             # the ISO 9283 report of a plan.kind: iso9283 run


def software_version() -> str:
    try:
        return version("robot-accuracy-campaign")
    except PackageNotFoundError:
        return "unknown"


def run_campaign(cfg: CampaignConfig, run_dir: Path | None = None, resume: Path | None = None,
                 console: Console | None = None, plan: Plan | None = None, overwrite: bool = False) -> RunResult:
    """Measure the plan of ``cfg`` (or the rest of it when resuming), then calibrate and report. ``run_dir`` must
    be new or empty (any directory but a run's with ``overwrite``: see :mod:`campaign.outputs`)."""
    console = console or stdout_console()
    if resume is not None:
        check_resume(resume, cfg)                           # every record's content vs plan.csv, fast
    else:
        run_dir = check_dir(default_run_dir(cfg) if run_dir is None else run_dir, RUN, overwrite)
    kin = nominal_kinematics(cfg)
    plan = build_plan(cfg, kin) if plan is None else plan      # given: campaign iso9283 with corrected cycles
    if not plan.points:
        raise ConfigError(cfg.source_path, "plan", f"no reachable point to measure ({len(plan.skipped)} skipped"
                          + (f", e.g. {plan.skipped[0].point_id}: {plan.skipped[0].reason})" if plan.skipped else ")"))
    if resume is not None:
        check_resume(resume, cfg, plan)                     # ... and vs the rebuilt plan, before anything connects
    with ExitStack() as stack:
        logging_ = stack.enter_context(run_logging(console))    # campaign.log once the run directory exists
        cell = stack.enter_context(open_cell(cfg))
        robot, tracker, clock = cell.robot, cell.tracker, cell.clock
        runner = Runner(robot, tracker, cfg.tracker.measurement, clock, lambda p: measurement_covariance(cfg, p[None])[0],
                        cfg.tool.payload_kg, n_smrs=len(cfg.tool.smrs_mm), nests=cfg.plan.nests)
        _safety(runner, cfg, kin, first_pass=resume is None)
        times = point_times_s(plan.points, cfg, kin)
        identity = device_identity(robot, tracker)
        identity["identity_check"] = check_identity(cfg, identity, is_forced())   # a mismatch: exit 2, nothing moved
        log, run_dir = open_log(cfg, plan, run_dir, resume, identity)
        stack.enter_context(closing_on_error(log))           # the runner closes it from execute on
        logging_.to_file(run_dir)
        if resume is not None:
            _continue_clock(clock, log.contents)
        for change in identity_changes(log.contents.start, identity) if resume else ():
            logger.warning("resuming on different hardware: %s", change)   # also in the devices event
        todo = pending(plan.points, completed_point_ids(log.contents) if resume else set())
        logger.info("run directory %s (%s), plan %s: %d of %d points to measure", run_dir,
                    "resumed" if resume else "new", plan.sha256[:12], len(todo), len(plan.points))
        left = np.isin([p.point_id for p in plan.points], [p.point_id for p in todo])
        eta = RunEta(times[0][left], times[1][left])
        runner.predict_p_tracker_mm = predictor = _smr_predictor(cfg, log.contents.records() if log.contents else ())
        runner.covariance_from_device = lambda c: device_measurement_covariance(cfg, c)
        with _progress(console, len(plan.points), len(plan.points) - len(todo), eta) as advance:
            runner.on_point = lambda point, record: (point.set == "nest" or predictor.observe(record.q_read_deg,
                                                                                          record.p_tracker_mm),
                                                     advance(record))
            if plan.blocks:                             # plan.stop: auto: block by block, refit after each
                from .adaptive import AdaptivePasses
                passes = AdaptivePasses(cfg, plan, run_dir, log, {p.point_id for p in plan.points} - {
                    p.point_id for p in todo}, on_skip=advance.skip)
                outcome = runner.execute_passes(passes, log)
            else:
                outcome = runner.execute(todo, log)
    if outcome.exit_status != "success":
        return RunResult(run_dir, outcome, None)
    from .iso_run import finish, is_iso_plan
    if is_iso_plan(plan):                       # acceptance test: ISO 9283 characteristics, no calibration
        iso = finish(cfg, run_dir)
        write_report(run_dir)
        return RunResult(run_dir, outcome, None, iso)
    contents = read_log(run_dir)
    dataset = dataset_from_log(contents)
    write_csv(run_dir / "data.csv", dataset)
    return RunResult(run_dir, outcome, _calibrate(dataset, cfg, run_dir, contents))


def reprocess(source: Path, cfg: CampaignConfig, out_dir: Path, overwrite: bool = False) -> Processed:
    """Offline: calibrate and report from a run directory (its log) or an interchange CSV file into ``out_dir``:
    new, empty, or written by reprocess from the same source (any but a run's with ``overwrite``)."""
    claim = check_dir(out_dir, "reprocess", overwrite, source=source_key(source))
    contents = read_log(source) if source.is_dir() else None
    dataset = dataset_from_log(contents) if contents is not None else read_csv(source)
    return _calibrate(dataset, cfg, claim, contents)


def _calibrate(dataset, cfg: CampaignConfig, out_dir: Path | Claim, contents=None) -> Processed:
    """Calibrate ``dataset``, write model/report files and report.html into ``out_dir`` (a run's directory, or a
    claim taken once the model exists); ``contents``: the log it came from (hardware identification)."""
    from .process import process, write_outputs     # the numerics load when calibrating, not at every start-up
    processed = process(dataset, cfg)
    if contents is not None:
        processed = replace(processed, report=processed.report.with_identification(identification(contents)))
        from .adaptive import stop_summary
        stop = stop_summary(contents, processed.report)
        if stop is not None:
            processed = replace(processed, report=replace(processed.report, stop=stop))
    if isinstance(out_dir, Claim):
        out_dir = out_dir.take()
    write_outputs(processed, out_dir)
    write_report(out_dir)                       # report.html from report.json
    return processed


def verify(run_dir: Path, console: Console | None = None):
    """Closed-loop verification of a finished run: corrected test points measured on the cell (logged durably
    in RUN_DIR/verify-TIMESTAMP/log.jsonl), before / after like seed 000 Table 3."""
    from .correction import verify_run
    from .config import load_config
    from .multi_smr import pose_estimator
    from .process import load_model

    cfg = load_config(run_dir / "config.yaml")
    model = load_model(run_dir / "model.json")
    records = read_log(run_dir).records()
    tests = [p for p in records if p.set == "test"]
    if not tests:
        raise CampaignError(f"{run_dir}: the run has no test points to verify")
    estimator = pose_estimator(cfg, model, records)       # three SMRs: 6D pose from SMR 1 (seed 003), fitted offline
    report_targets(run_dir)                                 # report.html and its figures are the run's to rewrite
    claim = check_dir(_new_path(run_dir / f"verify-{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}"),
                      "verify")
    out_dir = claim.path
    with ExitStack() as stack:
        logging_ = stack.enter_context(run_logging(console))
        cell = stack.enter_context(open_cell(cfg))
        robot, tracker = cell.robot, cell.tracker
        identity = device_identity(robot, tracker)
        identity["identity_check"] = check_identity(cfg, identity, is_forced())   # before the log and any move
        log = RunLog.create(out_dir, {"config_sha256": cfg.sha256, "plan_sha256": "verify", "run": str(run_dir),
                                      "software_version": software_version()} | identity)
        stack.enter_context(closing_on_error(log))           # the runner closes it from execute_passes on
        claim.take()
        logging_.to_file(out_dir)
        runner = Runner(robot, tracker, cfg.tracker.measurement, cell.clock,
                        lambda p: measurement_covariance(cfg, p[None])[0], cfg.tool.payload_kg)   # SMR 1 only
        _safety(runner, cfg, nominal_kinematics(cfg), first_pass=False)
        runner.predict_p_tracker_mm = _smr_predictor(cfg, records)
        runner.covariance_from_device = lambda c: device_measurement_covariance(cfg, c)
        result = verify_run(run_dir, lambda plan: runner.execute_passes(plan, log), cfg, model, tests, out_dir,
                            estimator)
    write_report(run_dir)                       # report.html now includes the verify passes
    return result


def _safety(runner: Runner, cfg: CampaignConfig, kin, first_pass: bool) -> None:
    """Speed caps, payload, swept-path guard and the optional reduced-speed first pass of a runner."""
    runner.limits, runner.payload, runner.guard = motion_limits(cfg), payload(cfg), PathGuard.from_config(cfg, kin)
    if first_pass and cfg.robot.first_pass_speed_pct is not None:
        runner.first_pass_limits = motion_limits(cfg, cfg.robot.first_pass_speed_pct)


def _smr_predictor(cfg: CampaignConfig, records) -> SmrPredictor:
    """Where to aim the tracker after a beam break: nominal model + registration from the point ``records`` measured
    so far (a resumed or verified run's), else the config's rough tracker position."""
    predictor = SmrPredictor(nominal_kinematics(cfg), cfg.tracker.position_in_base_mm)
    for record in records:
        if isinstance(record, PointRecord):                 # nest readings are not at the robot's SMR
            predictor.observe(record.q_read_deg, record.p_tracker_mm)
    return predictor


def open_log(cfg: CampaignConfig, plan: Plan, run_dir: Path | Claim | None, resume: Path | None,
             identity: dict | None = None) -> tuple[RunLog, Path]:
    """A new run directory (checked by :func:`campaign.outputs.check_dir` unless ``run_dir`` is a claim already)
    with its log, owner marker, config copy and plan CSV (its sha256 in the start record); or the resumed one
    after checking that neither the config nor the plan changed."""
    if resume is not None:
        check_unchanged(resume, read_log(resume).start, cfg, plan)      # before touching the log
        return RunLog.open_for_resume(resume), Path(resume)
    claim = run_dir if isinstance(run_dir, Claim) else check_dir(run_dir or default_run_dir(cfg), RUN)
    run_dir = claim.path
    plan_text = plan_csv_text(plan).encode("utf-8")
    log = RunLog.create(run_dir, start_record(cfg.to_dict(), cfg.sha256, plan.sha256, software_version(),
                                              datetime.now(timezone.utc).isoformat())
                        | {"plan_csv_sha256": hashlib.sha256(plan_text).hexdigest()} | (identity or {}))
    with closing_on_error(log):                             # the log never stays open without a stop record
        claim.take()
        copy_config(cfg, run_dir / "config.yaml")
        atomic_write(run_dir / "plan.csv", plan_text)
    return log, run_dir


def default_run_dir(cfg: CampaignConfig) -> Path:
    """output.dir/NAME-TIMESTAMP (UTC), see :func:`_new_path`."""
    return _new_path(Path(cfg.output.dir) / f"{cfg.name}-{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}")


def _new_path(base: Path) -> Path:
    """``base``, or ``base-2``, ``base-3``, ... when it exists already (two runs in the same second)."""
    path, k = base, 1
    while path.exists():
        k += 1
        path = base.with_name(f"{base.name}-{k}")
    return path


def copy_config(cfg: CampaignConfig, path: Path) -> None:
    """The run's copy of its config file (URL user-info and known secrets masked); ConfigError if the file changed
    since it was read."""
    from drivers.redact import redact

    data = Path(cfg.source_path).read_bytes()
    if hashlib.sha256(data).hexdigest() != cfg.sha256:
        raise ConfigError(cfg.source_path, "", "the file changed while the run started; start it again")
    atomic_write(path, redact(data.decode("utf-8-sig")).encode("utf-8"))


def _continue_clock(clock, contents) -> None:
    """A simulated cell's clock restarts at 0: move it on to the last time the resumed log holds, so that times
    keep increasing across sessions (a real cell's clock is the wall clock and needs nothing)."""
    if isinstance(clock, SystemClock) or contents is None:
        return
    times = [p.get("t_end_s") for p in contents.points] + [e.get("t_s") for e in contents.events]
    last = max((t for t in times if isinstance(t, (int, float))), default=0.0)
    if last > clock.now():
        clock.sleep(last - clock.now())


class _progress:
    """A rich progress bar with the run's ETA (tracker reading time and measured move times) on terminals;
    silent otherwise. Yields an ``advance(record)`` callable."""

    def __init__(self, console: Console, total: int, done: int, eta: RunEta | None = None):
        self.bar = Progress(TextColumn("measuring"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("{task.fields[eta]}"), console=console, disable=not console.is_terminal)
        self.total, self.done, self.eta = total, done, eta

    def __enter__(self):
        self.bar.start()
        text = self.eta.text() if self.eta else ""
        task = self.bar.add_task("points", total=self.total, completed=self.done, eta=text)

        def advance(record=None):
            if self.eta is not None and record is not None:
                self.eta.observe(record)
            self.bar.update(task, advance=1, eta=self.eta.text() if self.eta else "")

        def skip(n: int) -> None:                       # points a stop rule dropped from the plan
            self.total -= n
            if self.eta is not None:
                self.eta.skip(n)
            self.bar.update(task, total=self.total, eta=self.eta.text() if self.eta else "")
        advance.skip = skip
        return advance

    def __exit__(self, *exc):
        self.bar.stop()
        return False
