"""The cell's devices: ``open_devices(cell)`` opens and connects robot and tracker and closes them on exit.

Which drivers run is the registry's business (by URL); the simulated world behind ``mock://`` drivers is built
by the mock drivers themselves from the config's simulation section (``mock_world``), only when one is used."""
from __future__ import annotations

from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from drivers.base import Clock, Robot, Simulated, SystemClock, Tracker
from drivers.mock import MockWorld
from drivers.registry import CellContext, open_robot, open_tracker

from campaign.config.cell_model import CellModel
from campaign.config.schema import CampaignConfig
from campaign.config.simulation import simulated_cell


@dataclass(frozen=True)
class Devices:
    """A connected robot and tracker, and the clock of the cell (simulated time with mock drivers, s)."""
    robot: Robot
    tracker: Tracker
    clock: Clock


@contextmanager
def open_devices(cell: CellModel) -> Iterator[Devices]:
    """Open and connect the config's robot and tracker; both are closed on exit whatever happens."""
    cfg = cell.config
    with ExitStack() as stack:
        track = cfg.robot.track
        context = CellContext(n_joints=len(cfg.robot.joints), simulation=lambda: mock_world(cell),
                              track_unit=None if track is None else track.mechanical_unit)
        robot = open_robot(cfg.robot.url, cfg.robot.options, context)
        stack.callback(robot.close)
        options = {"timeout_s": cfg.tracker.measurement.timeout_s, **cfg.tracker.options}   # config timeout unless set
        tracker = open_tracker(cfg.tracker.url, options, context, robot)
        stack.callback(tracker.close)
        robot.connect()
        tracker.connect()
        simulated = next((d for d in (robot, tracker) if isinstance(d, Simulated) and d.simulated_clock), None)
        clock = simulated.simulated_clock if simulated is not None else SystemClock()
        yield Devices(robot, tracker, clock)


def mock_world(cell: CellModel) -> MockWorld:
    """The simulated cell behind mock:// drivers: the config's simulation section (truth, faults, phenomena)."""
    cfg = cell.config
    s = cfg.simulation
    faults = {"beam_break_probability": s.faults.beam_break_probability,
              "timeout_probability": s.faults.timeout_probability,
              "garbage_probability": s.faults.garbage_probability}
    offset = np.asarray(s.p_flange_smr_mm) - np.asarray(cfg.tool.p_flange_smr_mm)    # true vs nominal SMR 1
    extra = [tuple(np.asarray(p) + offset) for p in cfg.tool.smrs_mm[1:]]
    return MockWorld(simulated_cell(cell), s.seed, motion_time_s=s.motion_time_s,
                     joint_speed_deg_s=cfg.robot.max_joint_speed_deg_s, payload_kg=cfg.tool.payload_kg,
                     faults=faults, q0_deg=cfg.plan.q_ref_deg, extra_smrs_flange_mm=extra, **mock_phenomena(cfg))


def mock_phenomena(cfg: CampaignConfig) -> dict:
    """MockWorld keywords of the simulated read-back lag, tracker drift and reference nests."""
    s = cfg.simulation
    drift = (s.tracker_drift_mm_per_h, np.asarray(s.tracker_drift_urad_per_h) * 1e-6, s.tracker_drift_tau_s)
    return {"readback_lag_deg_per_deg": s.readback_lag_deg_per_deg or None, "readback_noise_deg": s.readback_noise_deg,
            "tracker_drift": drift if any(drift[0]) or np.any(drift[1]) else None,
            "nests": {n.id: n.p_base_mm for n in cfg.plan.nests.points}}
