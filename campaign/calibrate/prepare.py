"""Before calibration: which joint set drives the model, and the tracker drift seen by the reference nests.

``prepare(ds, cell)`` returns the dataset the calibration works on (robot rows only, one joint set, positions in
the tracker frame of the start of the run) and a report section saying what was chosen and why. Nothing mixes
the two joint sets: the chosen one becomes ``q_deg`` and ``qc_deg`` is dropped.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from robocal.measure.drift import DriftModel, fit_drift, nest_rounds
from robocal.identify.identification import CalibrationOptions, IdentificationError, calibrate
from robocal.measure.readback import ENCODER_NOISE_DEG, prefer_commanded, readback_statistics
from robocal.identify.screening import nest_misreads
from robocal.measure.stats import error_stats

from campaign.config.cell_model import CellModel
from campaign.errors import DataError
from campaign.data.dataset import Dataset


@dataclass(frozen=True, eq=False)
class Prepared:
    """``dataset``: robot rows, chosen joints in ``q_deg``, drift-corrected SMR positions; ``joints`` the set used
    (commanded | readback | as given); ``drift`` the nest drift model or None; ``report`` the JSON section."""
    dataset: Dataset
    joints: str
    drift: DriftModel | None
    report: dict


MIN_CALIB_ROWS = 10         # the fewest calibration rows a calibration fits (a fault screen may not leave fewer)
MAX_READBACK_RMS_DEG = 1.0   # read-back lags are hundredths of a degree; more means the two sets are not the same poses
FIT_MARGIN = 0.9    # the read-back set overrides the statistics only when it fits >= 10 % better


def _fit_rms(cell: CellModel, q_deg: np.ndarray, p_mm: np.ndarray) -> float | None:
    """RMS (mm) of a plain geometric LM fit of the calib rows with these joints (same model for both sets)."""
    try:
        res = calibrate(cell.kinematics, np.radians(q_deg), p_mm, cell.covariance(p_mm),
                        CalibrationOptions(method="lm", weights="none"))
    except (IdentificationError, np.linalg.LinAlgError, ValueError):
        return None
    return error_stats(res.residual_tracker_mm).rms_mm


def _confirm_by_fit(cell: CellModel | None, ds: Dataset, robot: np.ndarray) -> tuple[bool, str, dict]:
    """(keep commanded, why, figures): the statistics said the sets differ; which one do the measurements follow?
    The same geometric model is fitted to the calib rows with each set; the read-back set wins only when its
    RMS is clearly (>= 10 %) lower."""
    cal = ds.mask("calib")
    if cell is None or cal.sum() < MIN_CALIB_ROWS:
        return True, "", {}
    p = ds.p_tracker_mm[cal]
    rms_cmd, rms_read = _fit_rms(cell, ds.qc_deg[cal], p), _fit_rms(cell, ds.q_deg[cal], p)
    figs = {"geometric_fit_rms_commanded_mm": rms_cmd, "geometric_fit_rms_readback_mm": rms_read}
    if rms_cmd is None or rms_read is None:
        return True, "", figs
    if rms_read < FIT_MARGIN * rms_cmd:
        return False, (f"but the measurements follow the read-back joints (geometric fit RMS {rms_read:.4f} mm "
                       f"vs {rms_cmd:.4f} mm with the commanded ones)"), figs
    return True, f"; geometric fit RMS {rms_cmd:.4f} mm commanded vs {rms_read:.4f} mm read-back", figs


def choose_joints(ds: Dataset, setting: str, cell: CellModel | None = None) -> tuple[np.ndarray, str, dict]:
    """(q_deg (N, n) of the robot rows, set name, report) for ``calibration.joints`` = auto|commanded|readback.
    ``auto``: the read-back statistics decide (robocal.measure.readback.prefer_commanded); when they say the sets differ,
    a geometric fit with each set confirms it (with ``cell``; the read-back set wins only if it fits clearly
    better)."""
    robot = ds.mask("nest") == False  # noqa: E712
    if ds.qc_deg is None:
        if setting == "commanded":
            raise DataError(ds.source, "calibration.joints is 'commanded' but the data has no commanded joints "
                                       "(columns qc1..qcn)")
        return ds.q_deg[robot], "as given", {"used": "as given", "setting": setting,
                                            "why": "the data has one joint set only (q1..qn; no qc1..qcn)"}
    q_read, q_cmd = ds.q_deg[robot], ds.qc_deg[robot]
    s = readback_statistics(q_read, q_cmd)
    worst = int(np.argmax(s.rms_deg))
    if s.rms_deg[worst] > MAX_READBACK_RMS_DEG:
        raise DataError(ds.source, f"read-back and commanded joints differ by {s.rms_deg[worst]:.3g} deg RMS on "
                                   f"J{worst + 1} (q{worst + 1} vs qc{worst + 1}): not the same poses (units? column "
                                   f"order?); a read-back lag is below {MAX_READBACK_RMS_DEG:g} deg")
    commanded, why = prefer_commanded(s)
    figs: dict = {}
    if setting == "auto" and commanded:
        commanded, more, figs = _confirm_by_fit(cell, ds, robot)
        why = f"{why}{more}" if commanded else f"{why}, {more}"
    if setting != "auto":
        commanded = setting == "commanded"
        why = f"calibration.joints: {setting} (the automatic rule says: {why})"
    used = "commanded" if commanded else "readback"
    report = {"used": used, "setting": setting, "why": why, "encoder_noise_deg": ENCODER_NOISE_DEG,
              "readback_minus_command": s.to_dict(), **figs}
    return (q_cmd if commanded else q_read), used, report


def _nest_drift(ds: Dataset) -> tuple[DriftModel | None, dict]:
    """Drift model of the dataset's nest rows (None without nests), see :func:`fit_nest_drift`."""
    nest = ds.mask("nest")
    if not nest.any():
        return None, {"nests": 0, "applied": False, "why": "no reference-nest readings in the data", "excluded": []}
    if ds.t_s is None:
        raise DataError(ds.source, "nest rows need 't_s' (drift is a function of time)")
    return fit_nest_drift(ds.source, ds.t_s[nest], np.array(ds.nest_id)[nest], ds.p_tracker_mm[nest],
                          np.array(ds.point_id)[nest], float(np.max(ds.t_s)))


def fit_nest_drift(source: str, t_s: np.ndarray, nest_id: np.ndarray, p_tracker_mm: np.ndarray,
                   point_id: np.ndarray, t_end_s: float) -> tuple[DriftModel, dict]:
    """Drift model from nest readings (times t_s (M,) s from the registration's frame, nest ids (M,), readings
    (M, 3) mm tracker frame, point ids (M,)) and its report section (translation at ``t_end_s``): misread
    readings (a jump against the same nest's readings before and after, robocal.identify.screening.nest_misreads) are set
    aside and listed, the model is fitted on the rest. A nest read only once is bad input (DataError)."""
    t, ids, p = np.asarray(t_s, float), np.asarray(nest_id), np.asarray(p_tracker_mm, float)
    names, index, counts = np.unique(ids, return_inverse=True, return_counts=True)
    if (counts < 2).any():
        once = names[counts < 2]
        raise DataError(source, f"nest_id {str(once[0])!r} has a single reading{_more_names(once)}: a reference nest "
                                "must be read at least twice (start and end of the run) to show a drift")
    sc = nest_misreads(t, index, p)
    keep = sc.keep
    model = fit_drift(t[keep], index[keep], p[keep], tuple(names.tolist()), rounds=nest_rounds(index, t)[keep])
    pid = np.asarray(point_id)
    excluded = [{"point_id": str(pid[e.index]), "nest_id": str(ids[e.index]), "t_s": float(t[e.index]),
                 "reason": e.reason} for e in sc.excluded]
    tk, pk, ik = t[keep], p[keep], index[keep]
    first = np.array([pk[ik == k][np.argmin(tk[ik == k])] for k in range(len(names))])
    moved = np.linalg.norm(pk - first[ik], axis=1)
    t_end = np.array([float(t_end_s)])
    key = f"{model.degree}{'+rotation' if model.rotation else ''}"
    aside = f"; {len(excluded)} misread readings set aside (listed in 'excluded')" if excluded else ""
    report = {"nests": len(names), "readings": int(len(t)), "applied": model.degree > 0,
              "why": ("drift is significant: leave-one-round-out CV prefers degree "
                      f"{model.degree}{' with rotation' if model.rotation else ' (translation)'} over no drift"
                      if model.degree > 0 else
                      "no drift model beats constant nest positions in leave-one-round-out CV") + aside,
              "cv_rms_mm": model.cv_rms_mm.get(key),
              "excluded": excluded,
              "max_nest_move_mm": float(moved.max()),
              "translation_at_end_mm": model.translation_mm(t_end)[0].tolist() if model.degree else [0.0] * 3,
              "rotation_at_end_urad": (1e6 * model.rotation_rad(t_end)[0]).tolist() if model.degree else [0.0] * 3,
              "model": model.to_dict()}
    return model, report


def _more_names(names) -> str:
    return f" (and {', '.join(repr(str(n)) for n in names[1:4])}{' ...' if len(names) > 4 else ''})" \
        if len(names) > 1 else ""


def prepare(ds: Dataset, cell: CellModel) -> Prepared:
    """Joint set and nest drift of ``ds`` (see module doc) for the calibration of the cell."""
    q, used, joints_report = choose_joints(ds, cell.config.calibration.joints, cell)
    model, drift_report = _nest_drift(ds)
    robot = ~ds.mask("nest")
    out = ds.subset(robot) if not robot.all() else ds
    changes: dict = {"q_deg": q, "qc_deg": None, "nest_id": None}
    if model is not None and model.degree > 0:
        t = out.t_s
        for name in ("p_tracker_mm", "p2_tracker_mm", "p3_tracker_mm"):
            p = getattr(out, name)
            if p is not None:
                changes[name] = model.correct(p, t)
    out = replace(out, **changes)
    return Prepared(out, used, model, {"joints": joints_report, "drift": drift_report})
