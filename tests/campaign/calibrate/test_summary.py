"""The summary's verdict against acceptance bounds, and its JSON round trip."""
import pytest

from campaign.calibrate.report_sections import ErrorFigures
from campaign.calibrate.summary import (FAIL, NO_CRITERION, NO_TEST_SET, PASS, ChosenEffect, EffectValue,
                                        ModelSummary, Reasons, Summary, verdict)
from campaign.config.schema import AcceptanceConfig

HELD = ErrorFigures(max_mm=0.12, mean_mm=0.03, rms_mm=0.04, n=27)


@pytest.mark.unit
@pytest.mark.parametrize("bounds, result, failed", [
    ((None, None), NO_CRITERION, ()),
    ((0.05, None), PASS, ()),
    ((0.04, 0.12), PASS, ()),                        # a bound is inclusive
    ((0.03, None), FAIL, ("max_rms_mm",)),
    ((None, 0.1), FAIL, ("max_mm",)),
    ((0.01, 0.01), FAIL, ("max_rms_mm", "max_mm")),
])
def test_verdict_against_the_bounds(bounds, result, failed):
    v = verdict(HELD, AcceptanceConfig(*bounds))
    assert (v.result, v.failed, (v.max_rms_mm, v.max_mm)) == (result, failed, bounds)


@pytest.mark.unit
def test_no_verdict_without_a_test_set_or_a_criterion():
    assert verdict(None, AcceptanceConfig(0.05)).result == NO_TEST_SET
    assert verdict(HELD, None).result == NO_CRITERION


@pytest.mark.unit
def test_summary_round_trips_through_json():
    s = Summary(("robot", "tracker"),
                ModelSummary("dh", (2,), 22, 12, (ChosenEffect("backlash(J1,2)", (EffectValue("b1", 2.9e-4, "rad"),)),),
                             "gpr", "readback", "compensated"),
                Reasons("c", "p", "e", "r", "j", "d"), HELD, 0.028, 0.04 / 0.028, verdict(HELD, AcceptanceConfig(0.05)))
    assert Summary.from_dict(s.to_dict()) == s and s.simulated
    csv = Summary(None, s.model, s.reasons, None, 0.028, None, verdict(None, None))
    assert Summary.from_dict(csv.to_dict()) == csv and not csv.simulated
