"""The whole campaign in one place: config -> plan -> drivers -> durable log -> calibration -> report."""
from __future__ import annotations

import shutil
from contextlib import ExitStack
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from drivers.base import SystemClock
from drivers.mock import MockWorld
from drivers.registry import open_robot, open_tracker

from .cell import device_measurement_covariance, measurement_covariance, nominal_kinematics, simulated_cell
from .config import CampaignConfig
from .errors import CampaignError
from .interchange import dataset_from_log, read_csv, write_csv
from .plan import Plan, build_plan, write_plan_csv
from .process import Processed, process, write_outputs
from .runlog import RunLog, completed_point_ids, read_log
from .runner import RunOutcome, Runner, pending, start_record
from .tracker_quality import SmrPredictor


@dataclass(frozen=True)
class RunResult:
    run_dir: Path
    outcome: RunOutcome
    processed: Processed | None


def software_version() -> str:
    try:
        return version("robot-accuracy-campaign")
    except PackageNotFoundError:
        return "unknown"


def run_campaign(cfg: CampaignConfig, run_dir: Path | None = None, resume: Path | None = None,
                 console: Console | None = None) -> RunResult:
    """Measure the plan of ``cfg`` (or the rest of it when resuming), then calibrate and report."""
    console = console or Console()
    plan = build_plan(cfg, nominal_kinematics(cfg))
    world = mock_world(cfg) if "mock" in (_scheme(cfg.robot.url), _scheme(cfg.tracker.url)) else None
    clock = world.clock if world else SystemClock()
    with ExitStack() as stack:
        robot, tracker = _open_devices(cfg, world, stack)
        log, run_dir = open_log(cfg, plan, run_dir, resume)
        todo = pending(plan.points, completed_point_ids(log.contents) if resume else set())
        runner = Runner(robot, tracker, cfg.tracker.measurement, clock, lambda p: measurement_covariance(cfg, p[None])[0],
                        cfg.tool.payload_kg, n_smrs=len(cfg.tool.smrs_mm), nests=cfg.plan.nests)
        runner.predict_p_tracker_mm = predictor = _smr_predictor(cfg, log.contents.points if log.contents else ())
        runner.covariance_from_device = lambda c: device_measurement_covariance(cfg, c)
        with _progress(console, len(plan.points), len(plan.points) - len(todo)) as advance:
            runner.on_point = lambda point, record: (point.set == "nest" or predictor.observe(record["q_read_deg"],
                                                                                          record["p_tracker_mm"]),
                                                     advance())
            outcome = runner.execute(todo, log)
    if outcome.exit_status != "success":
        return RunResult(run_dir, outcome, None)
    dataset = dataset_from_log(read_log(run_dir))
    write_csv(run_dir / "data.csv", dataset)
    processed = process(dataset, cfg)
    write_outputs(processed, run_dir)
    return RunResult(run_dir, outcome, processed)


def reprocess(source: Path, cfg: CampaignConfig, out_dir: Path) -> Processed:
    """Offline: calibrate and report from a run directory (its log) or an interchange CSV file."""
    dataset = dataset_from_log(read_log(source)) if source.is_dir() else read_csv(source)
    processed = process(dataset, cfg)
    write_outputs(processed, out_dir)
    return processed


def verify(run_dir: Path, console: Console | None = None):
    """Closed-loop verification of a finished run: corrected test points measured on the cell (logged durably
    in RUN_DIR/verify-TIMESTAMP/log.jsonl), before / after like seed 000 Table 3."""
    from .correction import verify_run
    from .config import load_config
    from .process import load_model

    cfg = load_config(run_dir / "config.yaml")
    model = load_model(run_dir / "model.json")
    tests = [p for p in read_log(run_dir).points if p["set"] == "test"]
    if not tests:
        raise CampaignError(f"{run_dir}: the run has no test points to verify")
    out_dir = run_dir / f"verify-{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}"
    world = mock_world(cfg) if "mock" in (_scheme(cfg.robot.url), _scheme(cfg.tracker.url)) else None
    with ExitStack() as stack:
        robot, tracker = _open_devices(cfg, world, stack)
        log = RunLog.create(out_dir, {"config_sha256": cfg.sha256, "plan_sha256": "verify", "run": str(run_dir),
                                      "software_version": software_version()})
        runner = Runner(robot, tracker, cfg.tracker.measurement, world.clock if world else SystemClock(),
                        lambda p: measurement_covariance(cfg, p[None])[0], cfg.tool.payload_kg)   # SMR 1 only
        runner.predict_p_tracker_mm = _smr_predictor(cfg, read_log(run_dir).points)
        runner.covariance_from_device = lambda c: device_measurement_covariance(cfg, c)

        def measure(points):
            got = []
            runner.on_point = lambda point, record: got.append(record["p_tracker_mm"])
            outcome = runner.execute(points, log, close=False)
            return np.array(got), outcome.exit_status, outcome.reason

        result = verify_run(run_dir, measure, cfg, model, tests, out_dir)
        if not log.closed:
            log.close(result.exit_status, result.reason)
    return result


def _smr_predictor(cfg: CampaignConfig, records) -> SmrPredictor:
    """Where to aim the tracker after a beam break: nominal model + registration from the point ``records`` measured
    so far (a resumed or verified run's), else the config's rough tracker position."""
    predictor = SmrPredictor(nominal_kinematics(cfg), cfg.tracker.position_in_base_mm)
    for record in records:
        if record.get("q_read_deg") is not None and record.get("p_tracker_mm") is not None:
            predictor.observe(record["q_read_deg"], record["p_tracker_mm"])
    return predictor


def _open_devices(cfg: CampaignConfig, world: MockWorld | None, stack: ExitStack):
    """Open and connect robot and tracker; both are closed by ``stack`` whatever happens next."""
    robot = open_robot(cfg.robot.url, cfg.robot.options, world=world, n_joints=len(cfg.robot.joints))
    stack.callback(robot.close)
    options = {"timeout_s": cfg.tracker.measurement.timeout_s, **cfg.tracker.options}   # config timeout unless set
    tracker = open_tracker(cfg.tracker.url, options, world=world, robot=robot, clock=world.clock if world else None)
    stack.callback(tracker.close)
    robot.connect()
    tracker.connect()
    return robot, tracker


def mock_world(cfg: CampaignConfig) -> MockWorld:
    s = cfg.simulation
    faults = {"beam_break_probability": s.faults.beam_break_probability,
              "timeout_probability": s.faults.timeout_probability,
              "garbage_probability": s.faults.garbage_probability}
    offset = np.asarray(s.p_flange_smr_mm) - np.asarray(cfg.tool.p_flange_smr_mm)    # true vs nominal SMR 1
    extra = [tuple(np.asarray(p) + offset) for p in cfg.tool.smrs_mm[1:]]
    return MockWorld(simulated_cell(cfg), s.seed, motion_time_s=s.motion_time_s,
                     joint_speed_deg_s=cfg.robot.max_joint_speed_deg_s, payload_kg=cfg.tool.payload_kg,
                     faults=faults, q0_deg=cfg.plan.q_ref_deg, extra_smrs_flange_mm=extra, **mock_phenomena(cfg))


def mock_phenomena(cfg: CampaignConfig) -> dict:
    """MockWorld keywords of the simulated read-back lag, tracker drift and reference nests."""
    s = cfg.simulation
    drift = (s.tracker_drift_mm_per_h, np.asarray(s.tracker_drift_urad_per_h) * 1e-6, s.tracker_drift_tau_s)
    return {"readback_lag_deg_per_deg": s.readback_lag_deg_per_deg or None, "readback_noise_deg": s.readback_noise_deg,
            "tracker_drift": drift if any(drift[0]) or np.any(drift[1]) else None,
            "nests": {n.id: n.p_base_mm for n in cfg.plan.nests.points}}


def open_log(cfg: CampaignConfig, plan: Plan, run_dir: Path | None, resume: Path | None) -> tuple[RunLog, Path]:
    """A new run directory with its log, config copy and plan CSV; or the resumed one after checking that
    neither the config nor the plan changed."""
    if resume is not None:
        start = read_log(resume).start                      # check before touching the log
        if start.get("config_sha256") != cfg.sha256:
            raise CampaignError(f"{resume}: the config file changed since the run started; resume with the same config")
        if start.get("plan_sha256") != plan.sha256:
            raise CampaignError(f"{resume}: the plan differs from the one the run started with")
        return RunLog.open_for_resume(resume), Path(resume)
    if run_dir is None:
        stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
        run_dir = Path(cfg.output.dir) / f"{cfg.name}-{stamp}"
    run_dir = Path(run_dir)
    log = RunLog.create(run_dir, start_record(cfg.to_dict(), cfg.sha256, plan.sha256, software_version(),
                                              datetime.now(timezone.utc).isoformat()))
    shutil.copyfile(cfg.source_path, run_dir / "config.yaml")
    write_plan_csv(plan, run_dir / "plan.csv")
    return log, run_dir


def _scheme(url: str) -> str:
    return url.split("://", 1)[0]


class _progress:
    """A rich progress bar with ETA on terminals; silent otherwise. Yields an ``advance()`` callable."""

    def __init__(self, console: Console, total: int, done: int):
        self.bar = Progress(TextColumn("measuring"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                            console=console, disable=not console.is_terminal)
        self.total, self.done = total, done

    def __enter__(self):
        self.bar.start()
        task = self.bar.add_task("points", total=self.total, completed=self.done)
        return lambda: self.bar.advance(task)

    def __exit__(self, *exc):
        self.bar.stop()
        return False
