"""Plausibility checks run before any model is fitted or written: does this data belong to this robot?

* joint values outside the configured limits -> rejected rows, listed by line (CSV) or point record (log);
* the xyz unit guessed from the scale (spread of the measured points / spread of the nominal model's points):
  mm is stated, m / cm / inch is an error naming the factor;
* registration before plausibility: the base frame and the SMR offsets (one per SMR) are registration quantities,
  not robot parameters; they are fitted together on the nominal geometry first (:func:`robocal.identify.identification.register_tool`),
  and an SMR offset more than ``TOOL_NOTE_MM`` from the config is reported with the value to configure;
* nominal RMS after that registration on the calibration rows must be below 1 % of the robot's reach (wrong robot,
  wrong DH table, wrong joint order or offsets all fail it: "does this data belong to this robot?");
* identified joint deltas beyond physical bounds (a length change > max(5 mm, 2 % of the nominal length), an angle
  change > 2 deg) mean an error, not a model (base and SMR offsets are not bounded);
* a run directory whose log holds fewer points than its plan says so (an interrupted run is never silent).

A failed check raises :class:`campaign.errors.PlausibilityError` (exit 2, one line) unless the operator passed
``--force`` (``force=True``, passed by the command down to each check): then the rows outside the limits are dropped, and the report's
``plausibility.overridden`` lists every check that failed and was overridden.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping

import numpy as np

from campaign.config.cell_model import CellModel
from campaign.errors import DataError, PlausibilityError
from campaign.io.json_fields import count_field, figure_field, get_field, list_field, record_field, text_field

REACH_FRACTION = 0.01           # nominal RMS after registration must be < 1 % of the reach
LENGTH_DELTA_MM = 5.0           # identified length change bound: max(5 mm, 2 % of the nominal length)
LENGTH_DELTA_FRACTION = 0.02
ANGLE_DELTA_DEG = 2.0           # identified angle change bound (theta, alpha, beta)
MAX_ABS_MM = 1.0e6              # |xyz| beyond 1 km is not a tracker reading
LIMIT_TOL_DEG = 1e-6
TOOL_NOTE_MM = 3.0              # a registered SMR offset this far from the config is reported with the value to use
ON_AXIS_START_MM = 5.0          # fits start with an SMR offset this close to the flange axis on the axis
_UNITS = (("mm", 1.0), ("m", 1e-3), ("cm", 0.1), ("inch", 1 / 25.4))

@dataclass(frozen=True)
class ToolCheck:
    """The SMR offsets (flange frame, mm) registered with the base on the nominal geometry, one per SMR, against
    the configured ones; ``determined`` how many of the offset directions the poses' orientations determine."""
    configured_mm: tuple[tuple[float, float, float], ...]
    registered_mm: tuple[tuple[float, float, float], ...]
    determined: int

    @property
    def difference_mm(self) -> tuple[float, ...]:
        return tuple(float(np.linalg.norm(np.subtract(r, c))) for r, c in zip(self.registered_mm, self.configured_mm))

    def notes(self) -> tuple[str, ...]:
        """One line per SMR offset more than TOOL_NOTE_MM from the config, with the value to configure."""
        keys = ("tool.p_flange_smr_mm", "tool.p_flange_smr2_mm", "tool.p_flange_smr3_mm")
        return tuple(f"{key} is {_vec(c)} mm in the config but the data place the SMR at {_vec(r)} mm "
                     f"({d:.1f} mm away, registered with the base on the nominal geometry): put {_vec(r)} in {key}"
                     for key, c, r, d in zip(keys, self.configured_mm, self.registered_mm, self.difference_mm)
                     if d > TOOL_NOTE_MM)

    def to_dict(self) -> dict:
        return {"configured_mm": [list(c) for c in self.configured_mm],
                "registered_mm": [list(r) for r in self.registered_mm], "difference_mm": list(self.difference_mm),
                "directions_determined": self.determined, "note_above_mm": TOOL_NOTE_MM, "notes": list(self.notes())}

    @classmethod
    def from_dict(cls, d: Mapping) -> "ToolCheck":
        """The check of a report's ``plausibility.tool`` (differences and notes follow from the offsets)."""
        rows = lambda name: tuple(tuple(v) for v in list_field(d, name))  # noqa: E731
        return cls(rows("configured_mm"), rows("registered_mm"), count_field(d, "directions_determined"))


def _vec(v) -> str:
    return "[" + ", ".join(f"{x:.1f}" for x in v) + "]"


@dataclass(frozen=True)
class Plausibility:
    """What was checked: unit guess, nominal RMS vs its bound, rows rejected, notes, overridden failures."""
    unit: str = "mm"
    scale: float | None = None
    nominal_rms_mm: float | None = None
    bound_mm: float | None = None
    rejected_rows: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    overridden: tuple[str, ...] = ()
    forced: bool = False
    max_length_delta_mm: float | None = None
    max_angle_delta_deg: float | None = None
    tool: ToolCheck | None = None

    def to_dict(self) -> dict:
        return {"unit": self.unit, "scale": self.scale, "nominal_rms_mm": self.nominal_rms_mm,
                "bound_mm": self.bound_mm, "rejected_rows": list(self.rejected_rows), "notes": list(self.notes),
                "overridden": list(self.overridden), "forced": self.forced,
                "max_length_delta_mm": self.max_length_delta_mm, "max_angle_delta_deg": self.max_angle_delta_deg,
                "tool": None if self.tool is None else self.tool.to_dict()}

    @classmethod
    def from_dict(cls, d: Mapping) -> "Plausibility":
        """A report's ``plausibility`` section (keys added later than the report format are optional)."""
        texts = lambda name: tuple(list_field(d, name, True) or ())  # noqa: E731
        return cls(text_field(d, "unit", True) or "mm", figure_field(d, "scale"), figure_field(d, "nominal_rms_mm"),
                   figure_field(d, "bound_mm"), texts("rejected_rows"), texts("notes"), texts("overridden"),
                   bool(get_field(d, "forced", True)), figure_field(d, "max_length_delta_mm"),
                   figure_field(d, "max_angle_delta_deg"), record_field(d, "tool", ToolCheck.from_dict, True))


def _fail(source: str, message: str, state: Plausibility, force: bool) -> Plausibility:
    """Raise unless ``force``; then record the overridden failure."""
    if not force:
        raise PlausibilityError(source, message)
    return replace(state, overridden=state.overridden + (message,), forced=True)


def row_locations(ds) -> list[str]:
    """Human location of every row: ``line L`` of a CSV (comments and blank lines counted), else
    ``point record k``; the point id is appended."""
    src = Path(ds.source) if ds.source else None
    lines: list[int] | None = None
    if src is not None and src.is_file() and src.name != "log.jsonl":
        try:
            with open(src, encoding="utf-8-sig", newline="") as fh:
                numbered = [i + 1 for i, ln in enumerate(fh) if ln.strip() and not ln.lstrip().startswith("#")]
            lines = numbered[1:] if len(numbered) - 1 == len(ds) else None
        except (OSError, UnicodeDecodeError):
            lines = None
    if lines is None:
        return [f"point record {i + 1} ({pid})" for i, pid in enumerate(ds.point_id)]
    return [f"line {ln} ({pid})" for ln, pid in zip(lines, ds.point_id)]


def check_dataset(ds, cell: CellModel, *, force: bool = False):
    """Checks on the data alone (before any fit): magnitudes, joint limits, unit, nominal RMS, completeness.

    Unit and nominal RMS are judged on the rows inside the limits; every failed check is named in one line
    (the wrong-robot verdict first). Returns (dataset, Plausibility): the dataset without the rejected rows
    when ``force`` (``--force``: the failures are recorded as overridden), else unchanged."""
    cfg = cell.config
    state = Plausibility()
    ds.require_joints(len(cfg.robot.joints))
    ds = _check_magnitudes(ds)
    keep, state, limits_msg = _check_limits(ds, cfg, state)
    inside = ds.subset(keep) if limits_msg else ds
    state = _check_completeness(inside, state)
    failures = []
    cal = _calib_rows(inside)
    if cal.sum() >= 3:
        state, unit_msg = _check_unit(inside, cell, cal, state)
        state, nominal_msg = (state, None) if unit_msg else _check_nominal(inside, cell, cal, state)
        failures += [m for m in (nominal_msg, unit_msg) if m]
    if limits_msg:
        failures.append(limits_msg)
    if failures:
        if not force:
            raise PlausibilityError(ds.source, "; ".join(failures))
        state = replace(state, overridden=state.overridden + tuple(failures), forced=True)
    return inside, state


def _calib_rows(ds) -> np.ndarray:
    return ds.mask("calib") & np.all(np.isfinite(ds.q_deg), axis=1)


def _check_magnitudes(ds):
    """xyz beyond 1 km cannot be a tracker reading (and overflows every computation): a DataError, no override."""
    big = np.flatnonzero(np.any(np.abs(ds.p_tracker_mm) > MAX_ABS_MM, axis=1))
    if len(big):
        where = row_locations(ds)[big[0]]
        value = ds.p_tracker_mm[big[0]][np.argmax(np.abs(ds.p_tracker_mm[big[0]]))]
        raise DataError(ds.source, f"{where}: xyz value {value:.6g} mm is not a tracker reading "
                                   f"(|xyz| > {MAX_ABS_MM:.0e} mm){_more(len(big))}")
    return ds


def _more(n: int) -> str:
    return f"; {n - 1} more such rows" if n > 1 else ""


def _check_limits(ds, cfg, state: Plausibility):
    """Rows whose joint values lie outside the configured limits: listed, then an error (or dropped if forced)."""
    lo = np.array([j.q_min_deg for j in cfg.robot.joints]) - LIMIT_TOL_DEG
    hi = np.array([j.q_max_deg for j in cfg.robot.joints]) + LIMIT_TOL_DEG
    q = ds.q_deg
    if q.shape[1] != len(lo):
        return np.ones(len(ds), bool), state, None      # the joint-count check of the caller reports it
    finite = np.isfinite(q)
    outside = finite & ((q < lo) | (q > hi))
    bad = np.flatnonzero(np.any(outside, axis=1))
    keep = np.ones(len(ds), bool)
    if len(bad) == 0:
        return keep, state, None
    where = row_locations(ds)
    items = []
    for r in bad:
        j = int(np.flatnonzero(outside[r])[0])
        items.append(f"{where[r]}: q{j + 1} = {q[r, j]:.6g} deg outside "
                     f"[{cfg.robot.joints[j].q_min_deg:g}, {cfg.robot.joints[j].q_max_deg:g}]")
    shown = "; ".join(items[:3]) + (f"; and {len(items) - 3} more rows" if len(items) > 3 else "")
    keep[bad] = False
    return keep, replace(state, rejected_rows=tuple(items)), (
        f"{len(bad)} rows with joint values outside the configured limits: {shown}")


def _check_completeness(ds, state: Plausibility) -> Plausibility:
    """A run directory's log with fewer points than its plan: say how many of each set exist."""
    src = Path(ds.source) if ds.source else None
    if src is None or src.name != "log.jsonl":
        return state
    plan_csv = src.parent / "plan.csv"
    try:
        with open(plan_csv, newline="", encoding="utf-8") as fh:
            planned = [row[1] for row in list(csv.reader(fh))[1:] if len(row) > 1]
    except (OSError, UnicodeDecodeError, csv.Error):
        return state
    notes = []
    from .adaptive_stop import stopped_after                 # plan.stop: auto runs skip blocks on purpose
    stopped = stopped_after(src.parent)
    if stopped is not None and "candidate" in planned:          # plan.kind: adaptive: calib rows are chosen as it goes
        notes.append(f"plan.kind: adaptive stopped after {stopped} calibration points (report.json: stop)")
    elif stopped is not None:
        notes.append(f"plan.stop: auto stopped after {stopped} of {planned.count('calib')} planned calibration "
                     "points (report.json: stop)")
    for name in ("test",) if stopped is not None else ("calib", "test", "check"):
        want, have = planned.count(name), int(np.sum(ds.mask(name)))
        if have < want:
            notes.append(f"incomplete run: only {have} of {want} planned {name} points were measured")
    return replace(state, notes=state.notes + tuple(notes))


def _spread(p: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


def _check_unit(ds, cell: CellModel, cal: np.ndarray, state: Plausibility) -> tuple[Plausibility, str | None]:
    """Guess the xyz unit from the ratio of measured to nominal point spread (registration cannot fix scale)."""
    from robocal.kinematics.models import smr_base

    p_nom = smr_base(cell.kinematics, np.radians(ds.q_deg[cal]))
    s_nom, s_meas = _spread(p_nom), _spread(ds.p_tracker_mm[cal])
    if s_nom < 1e-6:
        return state, None
    scale = s_meas / s_nom
    unit = None if not scale > 0 else next(
        (name for name, f in _UNITS if abs(np.log(scale / f)) < np.log(1.25)), None)
    state = replace(state, scale=scale, unit=unit or "unknown")
    if unit == "mm":
        return state, None
    what = (f"xyz look like {unit}, not mm (measured spread {s_meas:.4g} vs {s_nom:.4g} mm for the nominal model, "
            f"scale {scale:.4g}): convert to mm") if unit else (
            f"xyz scale does not match the robot: measured spread {s_meas:.4g} vs {s_nom:.4g} mm for the nominal "
            f"model (scale {scale:.3g}, expected 1 for mm): does this data belong to this robot?")
    return state, what


def _register_tool(ds, cell: CellModel, cal: np.ndarray) -> ToolCheck | None:
    """Base and SMR offsets registered together on the nominal geometry (every SMR the config and the data have,
    on the calibration rows where all of them were read), or None when the rows cannot be registered."""
    from robocal.identify.identification import IdentificationError, register_tool

    cfg = cell.config
    clouds = [c for c in (ds.p_tracker_mm, ds.p2_tracker_mm, ds.p3_tracker_mm) if c is not None]
    clouds = clouds[:len(cfg.tool.smrs_mm)]
    P = np.stack([c[cal] for c in clouds])
    rows = np.all(np.isfinite(P), axis=(0, 2))
    configured = tuple(tuple(float(v) for v in s) for s in cfg.tool.smrs_mm[:len(clouds)])
    try:
        reg = register_tool(cell.kinematics, np.radians(ds.q_deg[cal][rows]), P[:, rows], configured)
    except (IdentificationError, np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(reg.p_flange_smr_mm)):
        return None
    return ToolCheck(configured, tuple(tuple(float(v) for v in r) for r in reg.p_flange_smr_mm), reg.determined)


def registered_kinematics(cell: CellModel, plaus: Plausibility | None = None):
    """The nominal model with the SMR offset registered by the plausibility check (the configured one when it
    could not be registered): the model of the ``nominal`` stage."""
    kin = cell.kinematics
    if plaus is None or plaus.tool is None:
        return kin
    return kin.with_(p_flange_smr_mm=np.array(plaus.tool.registered_mm[0]))


def start_kinematics(cell: CellModel, plaus: Plausibility | None = None):
    """The model every fit starts from: :func:`registered_kinematics`, with an SMR offset within ON_AXIS_START_MM
    of the flange axis put on the axis. From an on-axis start the calibration admits the wrist parameters that a
    small lateral lever makes only marginally identifiable when its solution identifies them strongly
    (:func:`robocal.identify.identification.calibrate`), so neither the configured lateral values nor a rough config decide which
    parameters are fitted (the fit identifies the lateral offset itself)."""
    kin = registered_kinematics(cell, plaus)
    p = kin.p_flange_smr_mm
    return kin.with_(p_flange_smr_mm=[0.0, 0.0, p[2]]) if np.hypot(p[0], p[1]) < ON_AXIS_START_MM else kin


def start_smr_offsets_mm(cfg, plaus: Plausibility | None = None) -> tuple:
    """Every SMR's start offset (flange frame, mm): registered where the check registered it, else configured."""
    got = () if plaus is None or plaus.tool is None else plaus.tool.registered_mm
    return tuple(got) + tuple(cfg.tool.smrs_mm[len(got):])


def _check_nominal(ds, cell: CellModel, cal: np.ndarray, state: Plausibility) -> tuple[Plausibility, str | None]:
    """Nominal RMS after registering the base and the SMR offsets on the calibration rows < 1 % of the reach."""
    from robocal.identify.identification import IdentificationError, register
    from robocal.identify.screening import reach_mm
    from robocal.kinematics.models import smr_tracker

    cfg = cell.config
    q, p = np.radians(ds.q_deg[cal]), ds.p_tracker_mm[cal]
    tool = _register_tool(ds, cell, cal)
    state = replace(state, tool=tool, notes=state.notes + (() if tool is None else tool.notes()))
    try:
        kin = register(registered_kinematics(cell, state), q, p)
    except (IdentificationError, np.linalg.LinAlgError):
        return state, None                  # calibration reports it with its own message
    err = p - smr_tracker(kin, q)
    rms = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    reach = reach_mm(kin)
    bound = REACH_FRACTION * reach
    state = replace(state, nominal_rms_mm=rms, bound_mm=bound)
    if not np.isfinite(rms) or rms > bound:
        return state, (f"does this data belong to this robot ({cfg.robot.model})? nominal error "
                       f"{rms:.0f} mm RMS after registration, more than {bound:.0f} mm (1 % of the "
                       f"{reach:.0f} mm reach)")
    return state, None


def check_deltas(kin0, kin, source: str, state: Plausibility, *, force: bool = False) -> Plausibility:
    """Identified joint geometry vs nominal: lengths within max(5 mm, 2 %), angles within 2 deg; else an error
    (recorded as overridden with ``force``). The base frame and the SMR offset are registration quantities and have
    no bound."""
    nominal_len = np.concatenate([kin0.a_mm, kin0.d_mm])
    delta_len = np.concatenate([kin.a_mm, kin.d_mm]) - nominal_len
    names = [f"a{i + 1}" for i in range(kin0.n)] + [f"d{i + 1}" for i in range(kin0.n)]
    bound = np.maximum(LENGTH_DELTA_MM, LENGTH_DELTA_FRACTION * np.abs(nominal_len))
    delta_ang = np.degrees(np.concatenate([kin.theta_rad - kin0.theta_rad, kin.alpha_rad - kin0.alpha_rad,
                                           kin.beta_rad - kin0.beta_rad]))
    delta_ang = (delta_ang + 180.0) % 360.0 - 180.0
    ang_names = ([f"theta{i + 1}" for i in range(kin0.n)] + [f"alpha{i + 1}" for i in range(kin0.n)]
                 + [f"beta{i + 1}" for i in range(kin0.n)])
    state = replace(state, max_length_delta_mm=float(np.max(np.abs(delta_len))),
                    max_angle_delta_deg=float(np.max(np.abs(delta_ang))))
    bad = [f"{n} {d:+.1f} mm (bound {b:.1f})" for n, d, b in zip(names, delta_len, bound) if abs(d) > b]
    bad += [f"{n} {d:+.2f} deg (bound {ANGLE_DELTA_DEG:g})" for n, d in zip(ang_names, delta_ang)
            if abs(d) > ANGLE_DELTA_DEG]
    if not bad:
        return state
    shown = ", ".join(bad[:4]) + (f" and {len(bad) - 4} more" if len(bad) > 4 else "")
    return _fail(source, f"identified deltas beyond physical bounds: {shown}: not a calibration of this robot "
                         "(wrong config, wrong data, or a crash)", state, force)



def plausibility_lines(plaus: Plausibility | None) -> list[tuple[str, str]]:
    """(text, rich style) lines stating what the plausibility checks found, for the terminal."""
    if plaus is None:
        return []
    scale = plaus.scale
    unit = f"xyz unit: {plaus.unit}" + (f" (scale {scale:.3f} of the nominal model)" if scale else "")
    if plaus.nominal_rms_mm is not None:
        unit += (f"; nominal RMS after registration {plaus.nominal_rms_mm:.3f} mm on the calibration points "
                 f"(plausible below {plaus.bound_mm:.0f} mm)")
    return ([(unit, "")] + [(note, "yellow") for note in plaus.notes]
            + [(f"OVERRIDDEN with --force: {what}", "bold red") for what in plaus.overridden])
