"""The ``plan`` section of the config schema: what to measure (grid, test set, check poses, reference nests,
ISO 9283 cube, candidate pool of optimal plans) and where the robot may go (keep-out boxes, envelope), as frozen
dataclasses; read by :mod:`campaign.config.sections`, part of :class:`campaign.config.schema.CampaignConfig`."""
from __future__ import annotations

from dataclasses import dataclass

from campaign.config.values import Vec3


@dataclass(frozen=True, slots=True)
class GridConfig:
    """Calibration grid: a box ``center_mm +- size_mm / 2`` in the robot base frame, sampled every ``step_mm``."""

    center_mm: Vec3
    size_mm: Vec3
    step_mm: float


@dataclass(frozen=True, slots=True)
class TestSetConfig:
    """Random validation points inside the grid box.

    Defaults: ``count`` 50 (int >= 0; 0 = no test set), ``seed`` 0 (int >= 0).
    """

    __test__ = False  # not a pytest test class despite the name

    count: int
    seed: int


@dataclass(frozen=True, slots=True)
class CheckPosesConfig:
    """Poses re-measured during the run (repeatability and drift).

    Defaults: ``count`` 0 (int >= 0), ``every_n_points`` 50 (int >= 1).
    """

    count: int
    every_n_points: int


@dataclass(frozen=True, slots=True)
class NestConfig:
    """One fixed reference nest: ``id`` (text), its approximate position ``p_base_mm`` in the robot base frame and,
    ``p_tracker_mm`` in the tracker frame: where a tracker that cannot find a nest by itself (emScon, the line
    protocol) aims; required for those trackers (checked before the first move), optional for the mock tracker."""

    id: str
    p_base_mm: Vec3
    p_tracker_mm: Vec3 | None = None


@dataclass(frozen=True, slots=True)
class NestsConfig:
    """Fixed floor nests re-measured through the run (tracker-registration drift).

    ``points`` (default none) the nests; each is measured at the start, after every ``every_n_points``
    robot points (int >= 1, default 50) and at the end; the tracker aims at the nest, the robot does not
    move. The run pauses when a nest reads more than ``max_move_mm`` (default 0.2 mm) from its first
    reading (tracker or nest disturbed).
    """

    points: tuple[NestConfig, ...] = ()
    every_n_points: int = 50
    max_move_mm: float = 0.2


@dataclass(frozen=True, slots=True)
class Iso9283Config:
    """ISO 9283 pose test (``plan.kind: iso9283``): the largest cube inside the grid box (or ``edge_mm``),
    P1-P5 on its diagonal plane, ``cycles`` cycles (default 30).

    Defaults: ``cycles`` 30 (int >= 3: a pose's RP and its uncertainty), ``edge_mm`` 0 = the largest cube inside
    the grid box.
    """

    cycles: int = 30
    edge_mm: float = 0.0


@dataclass(frozen=True, slots=True)
class PoolConfig:
    """Candidate poses of an optimal plan (``plan.kind: optimal``): positions every ``step_mm`` in the grid box
    (default half the grid step), ``tool_direction`` and ``tilts`` (default 6) directions tilted by ``tilt_deg``
    (default 20; tilts need ``tracker.position_in_base_mm``) around it, each on ``q_ref_deg``'s IK branch and,
    with ``wrist_flip`` (default true), on the flipped-wrist branch."""

    step_mm: float | None = None
    tilt_deg: float = 20.0
    tilts: int = 6
    wrist_flip: bool = True


@dataclass(frozen=True, slots=True)
class TaskConfig:
    """Where the robot will work: ``plan.kind: adaptive`` and ``campaign select --adaptive`` choose the poses that
    lower the predicted error there. One of ``targets_csv`` (Cartesian targets: the CSV of ``campaign correct``,
    ``target_id,x,y,z[,qw,qx,qy,qz]``, mm in the base frame; a path relative to the config file) or ``box_mm``
    (two opposite corners ``[[x0, y0, z0], [x1, y1, z1]]``, base frame). Without it the grid box stands for the
    task."""

    targets_csv: str | None = None
    box_mm: tuple[Vec3, Vec3] | None = None


@dataclass(frozen=True, slots=True)
class PlanConfig:
    """What to measure.

    ``tool_direction``: fixed flange z-axis in the base frame (non-zero, not
    normalised). ``q_ref_deg``: reference joint configuration (one value per
    joint, inside the limits) selecting the IK branch. ``test`` and
    ``check_poses`` are optional. ``nests`` (optional) reference nests;
    ``order`` ``serpentine`` (default: grid order, each test point next to its
    nearest grid point) or ``random`` (calib and test points shuffled with
    ``order_seed``, default 0).
    ``check_poses`` are optional. ``keep_out`` (default none), ``envelope``
    (default none) and ``clearance_mm`` (default 25): see ``BoxConfig``.
    ``kind``: ``grid`` (default), ``optimal`` (``points`` calibration poses chosen from a candidate ``pool``
    by a D-optimal criterion, measured in a short tour), ``adaptive`` (a space-filling seed from the ``pool``, then
    rounds of ``block_points`` poses (default 10) continuing it farthest-first, the model refitted to the points so far
    after each round deciding the stop, up to
    ``max_points``; ``stop`` defaults to ``auto``; ``task``: where the robot works) or ``iso9283``. ``stop: auto`` (optimal plans; default
    ``off``): refit after every ``block_points`` points (default 20) and stop when the predicted held-out RMS
    would improve by less than ``stop_gain_pct`` % of the noise floor (default 2) with the next block, or at
    ``max_points`` (default ``points``) or ``max_minutes`` (default none); then the test set is measured.
    ``track_stations`` (a robot on a track, grid plans; default 5): the grid, relative to the carriage, is measured
    with the carriage at this many stations evenly over the travel (grid points dealt to them in turn); test
    points at seeded random carriage positions anywhere on the travel.
    """

    grid: GridConfig
    test: TestSetConfig
    tool_direction: Vec3
    q_ref_deg: tuple[float, ...]
    check_poses: CheckPosesConfig
    nests: NestsConfig = NestsConfig()
    order: str = "serpentine"
    order_seed: int = 0
    keep_out: tuple["BoxConfig", ...] = ()
    envelope: "BoxConfig | None" = None
    clearance_mm: float = 25.0
    kind: str = "grid"                          # grid | optimal (calibration campaign) | iso9283 (acceptance test)
    iso9283: Iso9283Config = Iso9283Config()
    points: int | None = None                   # optimal: calibration points
    pool: PoolConfig = PoolConfig()
    stop: str = "off"                           # off | auto
    max_points: int | None = None
    max_minutes: float | None = None
    block_points: int = 20
    stop_gain_pct: float = 2.0
    track_stations: int | None = None           # a robot on a track: 5 unless given
    task: TaskConfig | None = None


@dataclass(frozen=True, slots=True)
class BoxConfig:
    """An axis-aligned box in the robot base frame (mm): ``min_mm`` < ``max_mm`` per axis; ``name`` for messages.

    ``plan.keep_out`` boxes must never be entered, ``plan.envelope`` never left, by the flange origin or any
    SMR centre (with ``plan.clearance_mm``, default 25) anywhere along the joint-interpolated path.
    """

    name: str
    min_mm: Vec3
    max_mm: Vec3
