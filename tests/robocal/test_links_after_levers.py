"""The link form of gravity compliance offered once the lever form is taken (``robocal.effects.library.
LINKS_AFTER_LEVERS``): the chain of refinements (the recovery through the default calibration:
tests/campaign/calibrate/test_links_after_levers.py)."""
from __future__ import annotations

from unittest import mock

import pytest

import robocal.effects.library as library
from robocal.effects.library import refinement_closure, refinements
from robocal.effects.model import EffectChoice

GRAVITY = EffectChoice("joint_compliance", (("joints", (2, 3)),))


def _form(choice: EffectChoice) -> str:
    return dict(choice.options).get("form", "gravity")


@pytest.mark.unit
def test_the_link_form_refines_the_lever_form_and_only_it():
    levers = refinements(GRAVITY, 6)
    assert [_form(c) for c in levers] == ["levers"]
    links = refinements(levers[0], 6)
    assert [_form(c) for c in links] == ["links"] and dict(links[0].options)["joints"] == (2, 3)
    assert refinements(links[0], 6) == []
    assert [_form(c) for c in refinement_closure([GRAVITY], 6)] == ["levers", "links"]
    assert refinement_closure([GRAVITY, *levers], 6) == links                 # candidates are not repeated
    with mock.patch.object(library, "LINKS_AFTER_LEVERS", False):
        assert refinements(levers[0], 6) == []
        assert [_form(c) for c in refinement_closure([GRAVITY], 6)] == ["levers"]
