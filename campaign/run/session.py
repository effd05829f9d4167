"""One measuring session on the cell: the run directory and its log (new, or resumed after the checks), the runner
(set up once: caps, payload, swept-path guard, measurement covariance, SMR predictor), and the progress bar with
the ETA."""
from __future__ import annotations

from datetime import datetime, timezone
import hashlib
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.errors import ConfigError
from campaign.io.durable import atomic_write
from campaign.plan.motion_safety import PathGuard, motion_limits, payload
from campaign.plan.points import Plan, plan_csv_text
from drivers.base import SelectsNest, SystemClock

from .devices import Devices
from .eta import RunEta
from .log_reader import read_log
from .log_records import PointRecord
from .log_writer import RunLog
from .output_dirs import RUN, Claim, check_dir, hold_lock
from .resume_checks import check_unchanged
from .runner import Runner, start_record
from .traceability import software_version
from .tracker_quality import SmrPredictor


def make_runner(cell: CellModel, devices: Devices, *, first_pass: bool = False, records=(),
                smr1_only: bool = False) -> Runner:
    """The runner of a session on ``devices``: speed caps, payload, swept-path guard, the reduced-speed first pass
    (``first_pass`` and configured), the logged covariance (the spec model, or the tracker's own + the robot's
    repeatability), and the beam-break SMR predictor seeded with ``records``; the reference nests, and every SMR
    of the tool or (``smr1_only``) SMR 1 only."""
    cfg = cell.config
    check_nest_aiming(cfg, devices.tracker)
    pct = cfg.robot.first_pass_speed_pct
    tool = {"nests": cfg.plan.nests} | ({} if smr1_only else {"n_smrs": len(cfg.tool.smrs_mm)})
    return Runner(devices.robot, devices.tracker, cfg.tracker.measurement, devices.clock,
                  lambda p: cell.covariance(p[None])[0], cfg.tool.payload_kg, **tool,
                  predict_p_tracker_mm=smr_predictor(cell, records), covariance_from_device=cell.device_covariance,
                  limits=motion_limits(cfg), payload=payload(cfg), guard=PathGuard.for_cell(cell),
                  first_pass_limits=motion_limits(cfg, pct) if first_pass and pct is not None else None)


def check_nest_aiming(cfg, tracker) -> None:
    """ConfigError (before anything moves) when a reference nest has no ``p_tracker_mm`` and the tracker cannot
    find a nest by itself (no ``select_nest``: emScon, the line protocol): it would not know where to aim."""
    if isinstance(tracker, SelectsNest):
        return
    for k, nest in enumerate(cfg.plan.nests.points):
        if nest.p_tracker_mm is None:
            raise ConfigError(cfg.source_path, f"plan.nests.points[{k}].p_tracker_mm",
                              f"nest {nest.id!r}: this tracker aims at a nest only from its tracker-frame position: "
                              "give p_tracker_mm (mm, tracker frame)")


def smr_predictor(cell: CellModel, records=()) -> SmrPredictor:
    """Where to aim the tracker after a beam break: nominal model + registration from the point ``records`` measured
    so far (a resumed or verified run's), else the config's rough tracker position."""
    predictor = SmrPredictor(cell.kinematics, cell.config.tracker.position_in_base_mm)
    observe_points(predictor, records)
    return predictor


def observe_points(predictor: SmrPredictor, records) -> None:
    """Feed the robot's point ``records`` to ``predictor`` (nest readings are not at the robot's SMR)."""
    for record in records:
        if isinstance(record, PointRecord):
            predictor.observe(record.q_read_deg, record.p_tracker_mm)


def open_log(cfg: CampaignConfig, plan: Plan, run_dir: Path | Claim | None, resume: Path | None,
             identity: dict | None = None) -> tuple[RunLog, Path]:
    """A new run directory (checked by :func:`campaign.run.output_dirs.check_dir` unless ``run_dir`` is a claim already)
    with its log, owner marker, config copy and plan CSV (its sha256 in the start record); or the resumed one
    after checking that neither the config nor the plan changed."""
    if resume is not None:
        hold_lock(Path(resume), "--resume")                # one process at a time in a run's directory
        check_unchanged(resume, read_log(resume).start, cfg, plan)      # before touching the log
        return RunLog.open_for_resume(resume), Path(resume)
    claim = run_dir if isinstance(run_dir, Claim) else check_dir(run_dir or default_run_dir(cfg), RUN)
    run_dir = claim.path
    plan_text = plan_csv_text(plan).encode("utf-8")
    # marker (and lock), config and plan first, the log last: a run stopped at any instant before its log holds
    # nothing measured, and --resume or --overwrite starts it again there
    claim.take()
    copy_config(cfg, run_dir / "config.yaml")
    atomic_write(run_dir / "plan.csv", plan_text)
    log = RunLog.create(run_dir, start_record(cfg.to_dict(), cfg.sha256, plan.sha256, software_version(),
                                              datetime.now(timezone.utc).isoformat())
                        | {"plan_csv_sha256": hashlib.sha256(plan_text).hexdigest()} | (identity or {}))
    return log, run_dir


def default_run_dir(cfg: CampaignConfig) -> Path:
    """output.dir/NAME-TIMESTAMP (UTC), see :func:`_new_path`."""
    return unique_path(Path(cfg.output.dir) / f"{cfg.name}-{datetime.now(timezone.utc).strftime('%Y%m%d-%H%M%S')}")


def unique_path(base: Path) -> Path:
    """``base``, or ``base-2``, ``base-3``, ... when it exists already (two runs in the same second)."""
    path, k = base, 1
    while path.exists():
        k += 1
        path = base.with_name(f"{base.name}-{k}")
    return path


def copy_config(cfg: CampaignConfig, path: Path) -> None:
    """The run's copy of its config file (URL user-info and known secrets masked); ConfigError if the file changed
    since it was read."""
    from drivers.redaction import redact

    data = Path(cfg.source_path).read_bytes()
    if hashlib.sha256(data).hexdigest() != cfg.sha256:
        raise ConfigError(cfg.source_path, "", "the file changed while the run started; start it again")
    atomic_write(path, redact(data.decode("utf-8-sig")).encode("utf-8"))


def continue_clock(clock, contents) -> None:
    """A simulated cell's clock restarts at 0: move it on to the last time the resumed log holds, so that times
    keep increasing across sessions (a real cell's clock is the wall clock and needs nothing)."""
    if isinstance(clock, SystemClock) or contents is None:
        return
    times = [r.t_end_s for r in contents.records()] + [e.get("t_s") for e in contents.events]
    last = max((t for t in times if isinstance(t, (int, float))), default=0.0)
    if last > clock.now():
        clock.sleep(last - clock.now())


class RunProgress:
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
