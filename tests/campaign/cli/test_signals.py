"""The unraisable hook of :mod:`campaign.signals`: silent about finaliser noise once a signal has arrived, and
only then."""
from __future__ import annotations

import sys
import types

import pytest

from campaign.cli import signals

pytestmark = pytest.mark.unit


def _dropped(exc: BaseException):
    return types.SimpleNamespace(exc_type=type(exc), exc_value=exc, exc_traceback=None, err_msg=None, object=None)


@pytest.fixture
def installed():
    seen = []
    previous, sys.unraisablehook = sys.unraisablehook, seen.append
    try:
        assert signals.install()
        yield seen
    finally:
        signals.restore()
        sys.unraisablehook = previous


def test_finaliser_error_is_reported_when_no_signal_arrived(installed):
    sys.unraisablehook(_dropped(AttributeError("'Forward' object has no attribute 'expr'")))
    assert len(installed) == 1                     # a real bug in a finaliser is not hidden


def test_finaliser_error_after_a_signal_is_silent(installed):
    signals._state.received = "SIGTERM"            # as the handler records it
    sys.unraisablehook(_dropped(AttributeError("'Forward' object has no attribute 'expr'")))
    assert installed == []
