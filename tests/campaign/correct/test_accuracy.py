"""The predicted errors of corrected targets and what ``correct`` says about them (campaign.correct.accuracy)."""
import dataclasses
import math

import numpy as np
import pytest

from campaign.correct.accuracy import HeldOut, predicted_errors_mm, rotation_errors_deg, summary_lines
from tests.campaign.correct.test_write_back import make_targets

pytestmark = pytest.mark.unit

KNOWN = HeldOut(0.030, "run/report.json", 94, 0.032, "repeats")
UNKNOWN = HeldOut(None, "no report.json beside model.json")


def test_predicted_error_is_the_held_out_rms_with_the_layers_std_and_the_solver_tolerance():
    err = predicted_errors_mm(KNOWN, np.array([np.nan, 0.040, np.nan]), np.array([0.0, 0.0, 0.040]))
    assert err.tolist() == pytest.approx([0.030, 0.050, 0.050], abs=1e-15)     # 3-4-5 in quadrature
    assert np.isnan(predicted_errors_mm(UNKNOWN, np.array([0.04]), np.array([0.0]))).all()


def test_rotation_error_is_predicted_only_where_orientation_was_measured():
    model_rad = np.radians([0.3, 0.0])
    assert np.isnan(rotation_errors_deg(KNOWN, model_rad)).all()           # one SMR: never measured
    three = dataclasses.replace(KNOWN, rot_rms_deg=0.4, rot_n=12)
    assert rotation_errors_deg(three, model_rad).tolist() == pytest.approx([0.5, 0.4])


def test_summary_names_the_source_and_keeps_the_solver_tolerance_apart():
    targets = [dataclasses.replace(t, predicted_error_mm=0.030, predicted_std_mm=math.nan,
                                   predicted_rot_err_deg=math.nan, solver_tolerance_mm=tol)
               for t, tol in zip(make_targets(3), (1e-7, 2e-5, 3e-4))]
    position, rotation, solver = summary_lines(targets, KNOWN, 1e-4)
    assert position == ("predicted position error (predicted_error_mm) 0.030 mm: held-out RMS 0.030 mm of the final "
                        "model on 94 test points (run/report.json; 0.94 x the noise floor 0.032 mm from the repeats)")
    assert "not predicted" in rotation and "predicted_rot_err_deg is nan" in rotation
    assert solver.startswith("solver tolerance (solver_tolerance_mm): the pseudo-target iteration left at most "
                             "3.00e-04 mm") and "1 target did not get there" in solver and "not an accuracy" in solver
    unknown = summary_lines([dataclasses.replace(t, predicted_error_mm=math.nan) for t in targets], UNKNOWN, 1e-4)
    assert unknown[0] == ("predicted position error: unknown (no report.json beside model.json); predicted_error_mm "
                          "is nan")
    assert summary_lines([], KNOWN, 1e-4) == []
