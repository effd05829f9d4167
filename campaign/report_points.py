"""Per-point section of report.json: what the HTML report's figures are drawn from.

Every row with joint values (calib, test, check) gets its id, set, joints (deg), measured SMR position in the
robot base frame (mm, through the calibrated registration) and, per stage, the error measured - predicted
(mm, base-frame axes). Rows without joints (reference nests) get their position only. Compact: rounded to 0.1 um
and 1e-4 deg, which is far below any figure the report shows.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np


def point_table(point_ids, sets, q_deg: np.ndarray, p_tracker_mm: np.ndarray, T_tracker_base: np.ndarray,
                predictions_tracker_mm: Mapping[str, Callable[[np.ndarray], np.ndarray]], used: np.ndarray,
                t_s: np.ndarray | None = None) -> dict:
    """The ``points`` dict of report.json.

    ``predictions_tracker_mm[stage](rows)`` -> predicted SMR positions (len(rows), 3) mm in the tracker frame for
    row indices ``rows``; ``used`` (N,): 1 = the row is in the fit, 0 = an excluded calib row, NaN = not a calib
    row."""
    q = np.asarray(q_deg, float)
    has_q = np.all(np.isfinite(q), axis=1)
    rows = np.flatnonzero(has_q)
    T = np.asarray(T_tracker_base, float)
    R = T[:3, :3]
    p_base = (np.asarray(p_tracker_mm, float) - T[:3, 3]) @ R          # R^T (p - t), row-wise
    err = {}
    for stage, predict in predictions_tracker_mm.items():
        e = np.full((len(q), 3), np.nan)
        e[rows] = (p_tracker_mm[rows] - predict(rows)) @ R
        err[stage] = _rounded(e, 4)
    return {"point_id": list(point_ids), "set": list(sets), "q_deg": _rounded(q, 4),
            "p_base_mm": _rounded(p_base, 4), "err_base_mm": err, "used": _rounded(used, 0),
            "t_s": None if t_s is None else _rounded(np.asarray(t_s, float), 3)}


def _rounded(a: np.ndarray, decimals: int) -> list:
    """Nested lists with NaN -> None (strict JSON)."""
    a = np.round(np.asarray(a, float), decimals)
    obj = a.astype(object)
    obj[~np.isfinite(a)] = None
    return obj.tolist()


def cell_summary(cfg) -> dict:
    """Cell identification and config summary for the report (from the campaign config)."""
    r, t, g = cfg.robot, cfg.tracker, cfg.plan.grid
    return {"robot_model": r.model, "robot_url": r.url, "convention": r.convention, "n_joints": len(r.joints),
            "hayati_joints": list(r.hayati_joints), "repeatability_mm": r.repeatability_mm,
            "tracker_model": t.model, "tracker_url": t.url, "p_flange_smr_mm": list(cfg.tool.p_flange_smr_mm),
            "payload_kg": cfg.tool.payload_kg, "grid_center_mm": list(g.center_mm), "grid_size_mm": list(g.size_mm),
            "grid_step_mm": g.step_mm}
