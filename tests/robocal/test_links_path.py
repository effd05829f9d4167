"""The second path of the effect selection (``robocal.effects.select.LINKS_PATH_GAIN``; issue 32's twentieth
protocol, bench/bench_links_path.py): with the links' form offered in place of the lever form, kept when its final
held-out RMS is lower by more than the share."""
from __future__ import annotations

from dataclasses import dataclass
from unittest import mock

import pytest

import robocal.effects.select as select
from robocal.effects.library import refinements
from robocal.effects.model import EffectChoice

pytestmark = pytest.mark.unit

GRAVITY = EffectChoice("joint_compliance", (("joints", (2, 3)), ("form", "gravity")))


def _compliance(form: str) -> EffectChoice:
    return EffectChoice("joint_compliance", (("joints", (2, 3)), ("form", form)))


@dataclass(frozen=True)
class _Path:
    taken: tuple
    final_cv_rms_mm: float
    path: str = ""


def _select(first, second, gain):
    """select_effects with ``_forward`` giving ``first`` (one path) or ``second`` (the links' path): (result,
    the refined forms of every call)."""
    calls = []

    def forward(*args, refined_forms=None):
        calls.append(refined_forms)
        return second if refined_forms else first
    with mock.patch.object(select, "_forward", forward), mock.patch.object(select, "LINKS_PATH_GAIN", gain):
        return select.select_effects(*[None] * 7), calls


def test_the_links_form_can_be_offered_in_place_of_the_lever_form():
    assert [dict(r.options)["form"] for r in refinements(GRAVITY, 6)] == ["levers"]
    assert [dict(r.options)["form"] for r in refinements(GRAVITY, 6, ("links",))] == ["links"]
    assert [dict(r.options)["form"] for r in refinements(_compliance("levers"), 6, ("links",))] == ["links"]


@pytest.mark.parametrize("links_mm, kept", [(0.0479, "links"), (0.0980, "levers"), (0.0990, "levers")])
def test_the_links_path_is_kept_only_when_lower_by_more_than_the_share(links_mm, kept):
    levers = _Path((_compliance("levers"),), 0.0995)
    links = _Path((_compliance("links"), EffectChoice("registration_drift")), links_mm)
    sel, calls = _select(levers, links, 0.02)
    assert calls == [None, ("links",)]
    assert sel.taken == (levers if kept == "levers" else links).taken
    assert f"kept the {'links' if kept == 'links' else 'lever form'}" in sel.path
    assert f"{links_mm:.4f} mm" in sel.path and "0.0995 mm" in sel.path


@pytest.mark.parametrize("taken", [(), (GRAVITY,), (_compliance("links"),),
                                   (_compliance("levers"), _compliance("links"))])
def test_one_path_unless_the_lever_form_is_taken_without_the_links_form(taken):
    sel, calls = _select(_Path(taken, 0.05), _Path((), 0.01), 0.02)
    assert calls == [None] and sel.path == "" and sel.taken == taken


def test_on_by_default_and_off_with_none():
    assert select.LINKS_PATH_GAIN == 0.02
    sel, calls = _select(_Path((_compliance("levers"),), 0.05), _Path((), 0.01), None)
    assert calls == [None] and sel.taken == (_compliance("levers"),)
