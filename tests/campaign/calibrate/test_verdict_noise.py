"""A criterion below what noise alone gives: named in the verdict against the measured floor (and in its wording),
and the largest noise-only error against a seeded simulation of it."""
import numpy as np
import pytest

from campaign.calibrate.report_sections import ErrorFigures
from campaign.calibrate.summary import FAIL, PASS, Summary, Verdict, verdict
from campaign.config.schema import AcceptanceConfig
from campaign.report.summary_text import lookup, verdict_line
from robocal.measure.noise import noise_max_mm

HELD = ErrorFigures(max_mm=0.077, mean_mm=0.029, rms_mm=0.032, n=94)


@pytest.mark.unit
@pytest.mark.parametrize("n", [1, 20, 94, 300])
def test_noise_max_is_the_median_largest_error_of_simulated_noise(n):
    floor = 0.032
    e = np.random.default_rng(n).normal(size=(3000, n, 3)) * floor / np.sqrt(3.0)
    simulated = np.median(np.linalg.norm(e, axis=2).max(axis=1))
    assert noise_max_mm(floor, n) == pytest.approx(simulated, rel=0.02)


@pytest.mark.unit
@pytest.mark.parametrize("bounds, result, below", [
    ((0.030, None), FAIL, ("max_rms_mm",)),          # under the floor 0.032: a perfect model fails it
    ((0.040, 0.050), FAIL, ("max_mm",)),             # under 0.064, the median largest of 94 noise-only errors
    ((0.040, 0.100), PASS, ()),                      # the demo's bounds
])
def test_bounds_below_the_measured_noise_are_named(bounds, result, below):
    v = verdict(HELD, AcceptanceConfig(*bounds), 0.032)
    assert (v.result, v.below_noise) == (result, below)
    assert v.noise_max_mm == pytest.approx(noise_max_mm(0.032, 94))
    assert Verdict.from_dict(v.to_dict()) == v
    assert verdict(HELD, AcceptanceConfig(*bounds)).below_noise == ()      # no floor given: nothing named


@pytest.mark.unit
def test_the_verdict_line_says_a_perfect_model_would_fail():
    v = verdict(HELD, AcceptanceConfig(0.030, 0.050), 0.032)
    s = Summary(None, None, None, HELD, 0.032, 1.0, v)
    doc = {"noise_floor_mm": 0.032, "verdict": v.to_dict(), "held_out": {"n": 94}}
    line = verdict_line(s, lambda key, kind: str(lookup(doc, key)))
    assert "note: a perfect model would fail these bounds more often than not" in line
    assert "RMS bound below the noise floor 0.032 mm" in line and "the median largest of 94 errors" in line
    passing = verdict(HELD, AcceptanceConfig(0.04, 0.1), 0.032)
    assert "note" not in verdict_line(Summary(None, None, None, HELD, 0.032, 1.0, passing), lambda key, kind: "1")
