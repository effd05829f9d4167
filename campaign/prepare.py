"""Before calibration: which joint set drives the model, and the tracker drift seen by the reference nests.

``prepare(ds, cfg)`` returns the dataset the calibration works on (robot rows only, one joint set, positions in
the tracker frame of the start of the run) and a report section saying what was chosen and why. Nothing mixes
the two joint sets: the chosen one becomes ``q_deg`` and ``qc_deg`` is dropped.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from robocal.drift import DriftModel, fit_drift
from robocal.readback import ENCODER_NOISE_DEG, prefer_commanded, readback_statistics

from .config import CampaignConfig
from .errors import DataError
from .interchange import Dataset


@dataclass(frozen=True, eq=False)
class Prepared:
    """``dataset``: robot rows, chosen joints in ``q_deg``, drift-corrected SMR positions; ``joints`` the set used
    (commanded | readback | as given); ``drift`` the nest drift model or None; ``report`` the JSON section."""
    dataset: Dataset
    joints: str
    drift: DriftModel | None
    report: dict


def choose_joints(ds: Dataset, setting: str) -> tuple[np.ndarray, str, dict]:
    """(q_deg (N, n) of the robot rows, set name, report) for ``calibration.joints`` = auto|commanded|readback."""
    robot = ds.mask("nest") == False  # noqa: E712
    if ds.qc_deg is None:
        if setting == "commanded":
            raise DataError(ds.source, "calibration.joints is 'commanded' but the data has no commanded joints "
                                       "(columns qc1..qcn)")
        return ds.q_deg[robot], "as given", {"used": "as given", "setting": setting,
                                            "why": "the data has one joint set only (q1..qn; no qc1..qcn)"}
    q_read, q_cmd = ds.q_deg[robot], ds.qc_deg[robot]
    s = readback_statistics(q_read, q_cmd)
    commanded, why = prefer_commanded(s)
    if setting != "auto":
        commanded = setting == "commanded"
        why = f"calibration.joints: {setting} (the automatic rule says: {why})"
    used = "commanded" if commanded else "readback"
    report = {"used": used, "setting": setting, "why": why, "encoder_noise_deg": ENCODER_NOISE_DEG,
              "readback_minus_command": s.to_dict()}
    return (q_cmd if commanded else q_read), used, report


def _nest_drift(ds: Dataset) -> tuple[DriftModel | None, dict]:
    """Drift model from the nest rows (None without nests)."""
    nest = ds.mask("nest")
    if not nest.any():
        return None, {"nests": 0, "applied": False, "why": "no reference-nest readings in the data"}
    if ds.t_s is None:
        raise DataError(ds.source, "nest rows need 't_s' (drift is a function of time)")
    ids = np.array(ds.nest_id)[nest]
    names, index = np.unique(ids, return_inverse=True)
    t, p = ds.t_s[nest], ds.p_tracker_mm[nest]
    model = fit_drift(t, index, p, tuple(names.tolist()))
    first = np.array([p[index == k][np.argmin(t[index == k])] for k in range(len(names))])
    moved = np.linalg.norm(p - first[index], axis=1)
    t_end = np.array([float(np.max(ds.t_s))])
    report = {"nests": len(names), "readings": int(nest.sum()), "applied": model.degree > 0,
              "why": ("drift is significant: leave-one-round-out CV prefers degree "
                      f"{model.degree}{' with rotation' if model.rotation else ' (translation)'} over no drift"
                      if model.degree > 0 else
                      "no drift model beats constant nest positions in leave-one-round-out CV"),
              "max_nest_move_mm": float(moved.max()),
              "translation_at_end_mm": model.translation_mm(t_end)[0].tolist() if model.degree else [0.0] * 3,
              "rotation_at_end_urad": (1e6 * model.rotation_rad(t_end)[0]).tolist() if model.degree else [0.0] * 3,
              "model": model.to_dict()}
    return model, report


def prepare(ds: Dataset, cfg: CampaignConfig) -> Prepared:
    """Joint set and nest drift of ``ds`` (see module doc) for the calibration of ``cfg``."""
    q, used, joints_report = choose_joints(ds, cfg.calibration.joints)
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
