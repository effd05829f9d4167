"""The glossary: every term the report defines is in docs/report.md too, and the condition number's scale words."""
import pytest

from campaign.report.glossary import GLOSSARY
from campaign.io.quantities import condition_scale, floor_mm
from tests.campaign.helpers import ROOT


@pytest.mark.unit
def test_every_glossary_term_is_in_the_docs():
    docs = " ".join((ROOT / "docs" / "report.md").read_text().split())
    for term, text in GLOSSARY:
        assert f"- **{term}**: {' '.join(text.split())}" in docs, term


@pytest.mark.unit
def test_condition_scale_and_floor_format():
    assert [condition_scale(v) for v in (12.0, 100.0, 101.0, 1e4, 1.35e5, None)] == \
        ["good", "good", "fair", "fair", "poor", "-"]
    assert (floor_mm(0.0325358), floor_mm(0.027924), floor_mm(None)) == ("0.033", "0.028", "-")
