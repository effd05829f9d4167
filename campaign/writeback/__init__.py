"""Write-back of corrected targets to robot controllers, behind safety bounds.

After calibration, target correction (``robocal.correct``) gives for each target
its nominal joints, corrected joints, the Cartesian command that reaches the
corrected joints with the controller's own nominal model, and the predicted
residual error.  This module

* checks the corrected targets against safety bounds (:func:`check_targets`):
  joint limits, the size of the joint correction, the size of the Cartesian
  correction and finiteness; a rejected target is reported, never written;
* writes the accepted targets for controllers and people:
  an ABB RAPID module (:func:`write_rapid_module`), Universal Robots JSON
  (:func:`write_ur_json`) and URScript (:func:`write_urscript`), and CSV
  (:func:`write_targets_csv`, :func:`write_rejected_csv`);  one module per format
  (``bounds``, ``rapid``, ``ur``, ``tables``), the RAPID checker and literals in ``drivers.rapid``;
* checks RAPID and URScript text (:func:`check_rapid_syntax`,
  :func:`check_urscript_syntax`) and reads RAPID data back
  (:func:`parse_rapid_module`), so every written file is verified.

Defence in depth: every target writer takes the joint limits again
(``q_min_deg``/``q_max_deg``) and raises :class:`ValueError`, writing nothing,
when a target breaks them or is otherwise invalid.  Every writer writes
atomically (temporary file, fsync, ``os.replace``, directory fsync) and its
output is a pure function of its arguments (no dates), so writing twice gives
identical bytes.

Units: joints in degrees (``*_deg``) or radians (``*_rad``), positions and
residuals in mm, quaternions unit (w, x, y, z).  See ``docs/writeback.md``.
"""

from __future__ import annotations


from drivers.rapid import RapidExpr, check_rapid_syntax, parse_rapid_module
from drivers.rapid.literals import RAPID_MAX_IDENT, RAPID_MAX_LINE, RAPID_MAX_LINE_ID, RAPID_MAX_STRING, RAPID_UNUSED

from .bounds import (GENERATOR, JOINT_DECIMALS, POSITION_DECIMALS, QUAT_DECIMALS, QUAT_UNIT_TOL, RAPID_FORMAT,
                     RESIDUAL_DECIMALS, UR_JSON_FORMAT, UR_MAX_A_RAD_S2, UR_MAX_V_RAD_S, UR_RAD_DECIMALS, URSCRIPT_FORMAT,
                     CorrectedTarget, Rejected, check_targets)
from .rapid import render_rapid_module, write_rapid_module
from .tables import read_corrected_targets_csv, render_targets_csv, write_rejected_csv, write_targets_csv
from .ur import check_urscript_syntax, render_ur_json, render_urscript, write_ur_json, write_urscript

__all__ = [
    "CorrectedTarget", "Rejected", "RapidExpr", "check_targets",
    "render_rapid_module", "write_rapid_module", "check_rapid_syntax", "parse_rapid_module",
    "render_ur_json", "write_ur_json", "render_urscript", "write_urscript", "check_urscript_syntax",
    "render_targets_csv", "write_targets_csv", "read_corrected_targets_csv", "write_rejected_csv",
]
