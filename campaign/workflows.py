"""The commands' workflows, built from the rooms: ``run_campaign`` (config -> plan -> devices -> durable log ->
calibration -> report), ``reprocess`` (a log or CSV -> model + report), ``select`` (N calibration rows of a measured
campaign -> interchange CSV), ``correct`` (targets + model -> controller files), ``diagnose`` (the sim-to-real gap
-> JSON, plots, HTML), ``verify`` (closed-loop passes with corrected targets) and ``run_iso9283`` (the ISO 9283
acceptance run). The library API the CLI and the tests call; the CLI only parses and prints. ``force``
(``--force``) overrides failed plausibility checks: it is passed down explicitly."""
from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass, replace
from datetime import datetime, timezone
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console

from campaign.config.cell_model import CellModel
from campaign.config.load import load_cell
from campaign.data.interchange_csv import write_csv
from campaign.data.memory_check import SELECT
from campaign.data.source import csv_provenance, load_source
from campaign.io.terminal_text import stdout_console
from campaign.plan.build import build_plan
from campaign.plan.acceptance import acceptance_warnings
from campaign.plan.iso9283 import IsoCube, is_iso_plan, iso_cube, iso_plan
from campaign.plan.points import Plan
from campaign.plan.poses import tool_rotation
from campaign.report.html import report_targets, write_report
from campaign.report.iso9283 import RUN_PREFIX as ISO_RUN_PREFIX, calibration_dir, finish, is_iso_run_of
from campaign.run.devices import open_devices
from campaign.run.eta import RunEta, point_times_s
from campaign.run.log_events import ExitStatus
from campaign.run.log_reader import completed_point_ids, read_log
from campaign.run.log_writer import RunLog
from campaign.run.output_dirs import RUN, Claim, check_dir, check_finished_run, not_started, source_key
from campaign.run.resume_checks import check_resume
from campaign.run.runner import RunOutcome, closing_on_error, pending
from campaign.run.session import (RunProgress, continue_clock, default_run_dir, make_runner, observe_points, open_log,
                                  unique_path)
from campaign.run.traceability import (check_identity, device_identity, identification, identity_changes, run_logging,
                                       software_version)
from drivers.base import SystemClock
from robocal.iso9283 import POSE_NAMES
from robocal.layers.calibrated_model import CalibratedModel

from .errors import CampaignError, ConfigError, DataError

if TYPE_CHECKING:
    from campaign.calibrate.stages import Calibrated


logger = logging.getLogger(__name__)
__all__ = ["RunResult", "run_campaign", "reprocess", "verify", "corrected_joints", "run_iso9283", "select", "correct", "diagnose",
           "DiagnoseOutputs"]


@dataclass(frozen=True)
class RunResult:
    run_dir: Path
    outcome: RunOutcome
    processed: Calibrated | None
    iso9283: dict | None = None             # the ISO 9283 report of a plan.kind: iso9283 run


def run_campaign(cell: CellModel, run_dir: Path | None = None, resume: Path | None = None,
                 console: Console | None = None, plan: Plan | None = None, overwrite: bool = False,
                 iso_model: tuple[CalibratedModel, Path] | None = None, *, force: bool = False) -> RunResult:
    """Measure the plan of the cell's config (or the rest of it when resuming), then calibrate and report.
    ``run_dir`` must be new or empty (any directory but a run's with ``overwrite``: see
    :mod:`campaign.run.output_dirs`). An ISO 9283 plan is reported instead of calibrated, in the frame of
    ``iso_model`` (the calibrated model and its file) when given."""
    cfg = cell.config
    console = console or stdout_console()
    if resume is not None and not_started(resume):          # stopped before its log: nothing was measured
        run_dir, resume, overwrite = Path(resume), None, True
        console.print(f"{run_dir} stopped before its first record (nothing was measured): starting it there again",
                      markup=False)
    if resume is not None:
        check_resume(resume, cfg)                           # every record's content vs plan.csv, fast
    else:
        run_dir = check_dir(default_run_dir(cfg) if run_dir is None else run_dir, RUN, overwrite)
    plan = build_plan(cell) if plan is None else plan          # given: campaign iso9283 with corrected cycles
    if not plan.points:
        raise ConfigError(cfg.source_path, "plan", f"no reachable point to measure ({len(plan.skipped)} skipped"
                          + (f", e.g. {plan.skipped[0].point_id}: {plan.skipped[0].reason})" if plan.skipped else ")"))
    if resume is not None:
        check_resume(resume, cfg, plan)                     # ... and vs the rebuilt plan, before anything connects
    with ExitStack() as stack:
        logging_ = stack.enter_context(run_logging(console))    # campaign.log once the run directory exists
        for line in [] if is_iso_plan(plan) else acceptance_warnings(cell, plan):   # before anything connects/moves
            logger.warning(line)
        devices = stack.enter_context(open_devices(cell))
        robot, tracker, clock = devices.robot, devices.tracker, devices.clock
        runner = make_runner(cell, devices, first_pass=resume is None)
        times = point_times_s(plan.points, cell)
        identity = device_identity(robot, tracker)
        identity["identity_check"] = check_identity(cfg, identity, force)   # a mismatch: exit 2, nothing moved
        log, run_dir = open_log(cfg, plan, run_dir, resume, identity)
        stack.enter_context(closing_on_error(log))           # the runner closes it from execute on
        logging_.to_file(run_dir)
        if resume is not None:
            continue_clock(clock, log.contents)
        elif cfg.plan.kind in ("optimal", "adaptive"):       # the forecast learning curve and minutes, for the report
            from campaign.calibrate.learning import forecast_event
            log.append_event(forecast_event(cell, plan))
        for change in identity_changes(log.contents.start, identity) if resume else ():
            logger.warning("resuming on different hardware: %s", change)   # also in the devices event
        todo = pending(plan.points, completed_point_ids(log.contents) if resume else set())
        logger.info("run directory %s (%s), plan %s: %d of %d points to measure", run_dir,
                    "resumed" if resume else "new", plan.sha256[:12], len(todo), len(plan.points))
        left = np.isin([p.point_id for p in plan.points], [p.point_id for p in todo])
        total, done = len(plan.points), len(plan.points) - len(todo)
        if plan.candidates:                             # plan.kind: adaptive: up to max_points, chosen as it goes
            extra = max(0, cfg.plan.max_points - plan.count("calib"))
            times = tuple(np.concatenate([t, np.full(extra, t[: plan.count("calib")].mean())]) for t in times)
            left = np.concatenate([left, np.ones(extra, bool)])
            total, done = total + extra, len(log.contents.records()) if resume else 0
        eta = RunEta(times[0][left], times[1][left], simulated=not isinstance(clock, SystemClock))
        predictor = runner.predict_p_tracker_mm
        observe_points(predictor, log.contents.records() if log.contents else ())     # resumed: the points so far
        with RunProgress(console, total, done, eta) as advance:
            runner.on_point = lambda point, record: (point.set == "nest" or predictor.observe(record.q_read_deg,
                                                                                          record.p_tracker_mm),
                                                     advance(record))
            if plan.candidates:                         # plan.kind: adaptive: rounds, the model refitted after each
                from campaign.calibrate.adaptive_rounds import AdaptiveRounds
                passes = AdaptiveRounds(cell, plan, run_dir, log, {p.point_id for p in plan.points} - {
                    p.point_id for p in todo}, on_skip=advance.skip, force=force)
                outcome = runner.execute_passes(passes, log)
            elif plan.blocks:                           # plan.stop: auto: block by block, refit after each
                from campaign.calibrate.adaptive_stop import AdaptivePasses
                passes = AdaptivePasses(cell, plan, run_dir, log, {p.point_id for p in plan.points} - {
                    p.point_id for p in todo}, on_skip=advance.skip)
                outcome = runner.execute_passes(passes, log)
            else:
                outcome = runner.execute(todo, log)
    if outcome.exit_status != ExitStatus.SUCCESS:
        return RunResult(run_dir, outcome, None)
    if is_iso_plan(plan):                       # acceptance test: ISO 9283 characteristics, no calibration
        iso = finish(cell, run_dir, *(iso_model or ()))
        write_report(run_dir)
        return RunResult(run_dir, outcome, None, iso)
    source = load_source(run_dir)
    write_csv(run_dir / "data.csv", source.dataset)
    return RunResult(run_dir, outcome, _calibrate(source.dataset, cell, run_dir, source.contents, force=force))


def reprocess(source: Path, cell: CellModel, out_dir: Path, overwrite: bool = False, *,
              force: bool = False) -> Calibrated:
    """Offline: calibrate and report from a run directory (its log) or an interchange CSV file into ``out_dir``:
    new, empty, or written by reprocess from the same source (any but a run's with ``overwrite``)."""
    claim = check_dir(out_dir, "reprocess", overwrite, source=source_key(source))
    data = load_source(source)
    return _calibrate(data.dataset, cell, claim, data.contents, force=force)


def _calibrate(dataset, cell: CellModel, out_dir: Path | Claim, contents=None, *, force: bool = False) -> Calibrated:
    """Calibrate ``dataset``, write model/report files and report.html into ``out_dir`` (a run's directory, or a
    claim taken once the model exists); ``contents``: the log it came from (hardware identification)."""
    from campaign.calibrate.stages import calibrate_dataset
    from campaign.calibrate.outputs import write_outputs     # the numerics load when calibrating, not at every start-up
    from campaign.calibrate.summary import summarize
    processed = calibrate_dataset(dataset, cell, force=force)
    if contents is not None:
        processed = replace(processed, report=processed.report.with_identification(identification(contents)))
        from campaign.calibrate.adaptive_stop import stop_summary
        final = processed.report.final
        stop = stop_summary(contents, None if final is None else final.test.rms_mm)
        if stop is not None:
            processed = replace(processed, report=replace(processed.report, stop=stop))
        from campaign.calibrate.learning import learning_summary
        learning = learning_summary(dataset, cell, contents, None if final is None else final.test.rms_mm,
                                    force=force)
        if learning is not None:
            processed = replace(processed, report=replace(processed.report, learning=learning))
    else:                                       # an interchange CSV: where it came from, no device named
        processed = replace(processed, report=processed.report.without_devices(csv_provenance(dataset)))
    processed = replace(processed, report=replace(processed.report,
                                                  summary=summarize(processed.report, cell.config.acceptance)))
    if isinstance(out_dir, Claim):
        out_dir = out_dir.take()
    write_outputs(processed, out_dir)
    write_report(out_dir)                       # report.html from report.json
    return processed


def verify(run_dir: Path, console: Console | None = None, *, force: bool = False):
    """Closed-loop verification of a finished run: corrected test points measured on the cell (logged durably
    in RUN_DIR/verify-TIMESTAMP/log.jsonl), before / after like seed 000 Table 3; with reference nests in the
    config they are read at the start and after every pass, and every measurement is compared in the
    calibration's tracker frame (``campaign.correct.verify_drift``)."""
    from campaign.correct.verify import verify_run
    from campaign.correct.verify_drift import VerifyDrift
    from campaign.calibrate.multi_smr import pose_estimator
    from campaign.calibrate.outputs import load_model

    check_finished_run(run_dir, "verify")
    cell = load_cell(run_dir / "config.yaml")
    cfg = cell.config
    model = load_model(run_dir / "model.json")
    contents = read_log(run_dir)
    records = contents.records()
    tests = [p for p in records if p.set == "test"]
    if not tests:
        raise CampaignError(f"{run_dir}: the run has no test points to verify")
    estimator = pose_estimator(cell, model, records)       # three SMRs: 6D pose from SMR 1 (seed 003), fitted offline
    report_targets(run_dir)                                 # report.html and its figures are the run's to rewrite
    claim = check_dir(unique_path(run_dir / f"verify-{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}"),
                      "verify")
    out_dir = claim.path
    with ExitStack() as stack:
        logging_ = stack.enter_context(run_logging(console))
        devices = stack.enter_context(open_devices(cell))
        robot, tracker = devices.robot, devices.tracker
        continue_clock(devices.clock, contents)             # a simulated cell's time (and drift) goes on from the run
        identity = device_identity(robot, tracker)
        identity["identity_check"] = check_identity(cfg, identity, force)   # before the log and any move
        claim.take()                                        # the marker (and lock) before the log
        log = RunLog.create(out_dir, {"config_sha256": cfg.sha256, "plan_sha256": "verify", "run": str(run_dir),
                                      "software_version": software_version()} | identity)
        stack.enter_context(closing_on_error(log))           # the runner closes it from execute_passes on
        logging_.to_file(out_dir)
        runner = make_runner(cell, devices, records=records, smr1_only=True)

        def execute(plan):
            runner.on_point = plan.observe                   # nest readings and point times, once on disk
            return runner.execute_passes(plan, log)
        result = verify_run(run_dir, execute, cell, model, tests, out_dir, estimator,
                            VerifyDrift(cfg.plan.nests, records, str(run_dir)))
    write_report(run_dir)                       # report.html now includes the verify passes
    return result


def corrected_joints(cell: CellModel, model: CalibratedModel, cube: IsoCube) -> np.ndarray:
    """Corrected joints (5, n) deg for P1..P5 with the calibrated model; every pose must pass the bounds."""
    from campaign.correct.targets import Targets, correct_targets

    R = tool_rotation(cell.config.plan.tool_direction)
    accepted, rejected = correct_targets(cell, model, Targets(POSE_NAMES, cube.p_base_mm, np.repeat(R[None], 5, 0)))
    if rejected:
        raise CampaignError(f"ISO 9283 pose {rejected[0].target_id} cannot be corrected: {rejected[0].reason}")
    by_id = {t.target_id: t for t in accepted}
    return np.array([by_id[name].q_corrected_deg for name in POSE_NAMES])


def run_iso9283(cell: CellModel, model: CalibratedModel | None, run_dir=None, console=None,
                overwrite: bool = False, model_path: Path | None = None):
    """``campaign iso9283``: nominal cycles, then (with a model) corrected cycles, through ``run_campaign`` (same
    safety, log and lifecycle); returns (RunResult, report or None). With a model written by ``run`` or
    ``reprocess`` (``model_path`` in a directory with its calibration report), the run goes by default to
    ``DIR/iso9283-TIMESTAMP`` and DIR's report.html is written again to list it (checked before anything moves)."""
    cube = iso_cube(cell)
    plan = iso_plan(cell, None if model is None else corrected_joints(cell, model, cube))
    cal_dir = None if model_path is None else calibration_dir(model_path)
    if cal_dir is not None and run_dir is None:
        run_dir = unique_path(cal_dir / f"{ISO_RUN_PREFIX}{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}")
    if cal_dir is not None and is_iso_run_of(run_dir, cal_dir):
        report_targets(cal_dir)                                 # its report.html is the calibration's to rewrite
    result = run_campaign(cell, run_dir, None, console, plan=plan, overwrite=overwrite,
                          iso_model=None if model is None else (model, model_path))
    if result.iso9283 is not None and cal_dir is not None and is_iso_run_of(result.run_dir, cal_dir):
        write_report(cal_dir)                                   # the calibration report lists its ISO reports
    return result, result.iso9283


def select(data: Path, cell: CellModel, n: int, out: Path, *, adaptive: bool = False, overwrite: bool = False,
           force: bool = False):
    """``campaign select``: ``n`` calibration rows of a measured campaign (a run directory or an interchange CSV),
    space-filling with the geometry determined (``adaptive``: replayed batch by batch with the model refitted),
    written to ``out`` as an interchange CSV (each kept row with how the robot reached it). Returns (the selection,
    the dataset it was chosen from)."""
    from campaign.calibrate.selection import select_rows
    from campaign.run.output_dirs import check_file

    if n < 1:
        raise DataError(str(data), f"--points must be a positive number of rows, got {n}")
    if out.resolve() == data.resolve():
        raise DataError(str(out), "the subset would overwrite its source; choose another --out")
    check_file(out, overwrite)
    ds = load_source(data, SELECT).dataset
    if adaptive:
        from campaign.calibrate.select_adaptive import adaptive_selection
        sel = adaptive_selection(ds, cell, n, force=force)
    else:
        sel = select_rows(ds, cell, n, force=force)
    subset = ds.with_order_context().subset(sel.keep)              # each kept row: how the robot reached it
    origin = f"{len(subset)} of {len(ds)} rows selected from {data} (campaign select)"
    write_csv(out, replace(subset, provenance=f"{origin}; {ds.provenance}" if ds.provenance else origin))
    return sel, ds


@dataclass(frozen=True)
class CorrectResult:
    """What ``correct`` wrote: the files, the number of targets, those refused (rejected.csv), the corrected
    targets written and the model's held-out accuracy record (None if unknown)."""
    paths: list
    n_targets: int
    refused: set
    written: list
    held_out: object


def correct(cell: CellModel, model_path: Path, targets_path: Path, out: Path, formats: tuple[str, ...] = (), *,
            overwrite: bool = False, force: bool = False, on_rejected=None) -> CorrectResult:
    """``campaign correct``: Cartesian targets corrected with the calibrated model at ``model_path`` (it must
    describe the config's robot) and written as controller files in ``out`` (``formats``: default the configured
    controller's and csv) with rejected.csv; ``on_rejected(n_targets)`` is called once rejected.csv is written,
    also when no target is left to write (CampaignError then)."""
    from campaign.calibrate.outputs import load_model
    from campaign.correct.accuracy import held_out_of
    from campaign.correct.targets import check_model_fits, correct_targets, read_targets_csv, recorded_identity
    from campaign.correct.write_back import read_rejected, write_corrected

    claim = check_dir(out, "correct", overwrite, source=source_key(model_path))
    model = load_model(model_path)
    check_model_fits(cell, model, str(model_path), force=force)
    targets = read_targets_csv(targets_path, tool_rotation(cell.config.plan.tool_direction))
    held = held_out_of(model, model_path)
    accepted, rejected = correct_targets(cell, model, targets, robot_identity=recorded_identity(model, model_path),
                                         held_out=held)
    try:
        paths = write_corrected(cell.config, accepted, rejected, claim.take(), tuple(formats))
    finally:
        if on_rejected is not None:
            on_rejected(len(targets.ids))
    refused = {target_id for target_id, _ in read_rejected(out)}
    return CorrectResult(paths, len(targets.ids), refused, [t for t in accepted if t.target_id not in refused], held)


@dataclass(frozen=True)
class DiagnoseOutputs:
    """Where ``diagnose`` writes besides the terminal: ``json`` (a file), ``plots`` (a directory), ``html`` (a file;
    None for a run directory: its own report.html with diagnosis.json beside it)."""
    json: Path | None = None
    plots: Path | None = None
    html: Path | None = None
    overwrite: bool = False


def diagnose(source: Path, cell: CellModel, outputs: DiagnoseOutputs = DiagnoseOutputs(), *, force: bool = False,
             on_written=None):
    """``campaign diagnose``: the sim-to-real gap of a run directory or CSV. Every output path is checked before
    any work; returns the :class:`DiagnosisReport` and ``write()``, which writes the outputs and calls
    ``on_written(line)`` after each ("wrote PATH", or the note when matplotlib is missing)."""
    from campaign.calibrate.diagnosis import diagnose_source

    plots = _diagnosis_targets(source, outputs)
    result = diagnose_source(source, cell, force=force)

    def write() -> None:
        say = on_written or (lambda line: None)
        from campaign.calibrate.diagnosis import write_diagnosis_json
        if outputs.json:
            write_diagnosis_json(outputs.json, result.report)
            say(f"wrote {outputs.json}")
        if plots is not None:
            from campaign.report.diagnosis_plots import write_plots
            files = write_plots(result.report, plots)
            say(files if isinstance(files, str) else f"wrote {', '.join(str(f) for f in files)}")
        html = _diagnosis_html(source, outputs, result.report)
        if html:
            say(f"wrote {html}")
    return result, write


def _diagnosis_targets(source: Path, outputs: DiagnoseOutputs):
    """--json FILE, --plots DIR, --html FILE (or the run directory's diagnosis.json and report.html) checked
    (:mod:`campaign.run.output_dirs`); returns the claim of the plots directory (None without --plots)."""
    from campaign.run.output_dirs import check_campaign_dir, check_file

    if outputs.json:
        check_file(outputs.json, outputs.overwrite, "--json")
    if outputs.html is not None:                  # a page of the diagnosis alone: never a run's own report.html
        check_file(outputs.html, outputs.overwrite, "--html")
        report_targets(outputs.html.parent, outputs.html, outputs.overwrite)
    elif source.is_dir():
        check_campaign_dir(source, "diagnose")
        report_targets(source)
    if outputs.plots is None:
        return None
    return check_dir(outputs.plots, "plots", outputs.overwrite, source=source_key(source), option="--plots")


def _diagnosis_html(source: Path, outputs: DiagnoseOutputs, report: dict) -> Path | None:
    """The diagnosis as an HTML report: --html FILE (from the diagnosis alone), or the run directory's
    report.html with diagnosis.json beside it."""
    from campaign.calibrate.diagnosis import write_diagnosis_json
    from campaign.report.html import ReportSources

    if outputs.html is not None:
        title = f"{report.get('config', 'diagnosis')}: {outputs.html.stem}"
        return write_report(outputs.html.parent, outputs.html, outputs.overwrite,
                            sources=ReportSources(title, diagnosis=report, files={"diagnosis": "(this command)"}))
    if not source.is_dir():
        return None
    write_diagnosis_json(source / "diagnosis.json", report)
    return write_report(source)
