"""The unraisable and exception hooks of :mod:`campaign.signals`: silent about finaliser and import noise once a
signal has arrived, and only then; a library's own error after a signal exits 130."""
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


def test_exception_printed_by_c_code_after_a_signal_is_silent(installed, capsys):
    signals._state.received = "SIGTERM"
    sys.excepthook(ImportError, ImportError("numpy._core.multiarray failed to import"), None)
    assert capsys.readouterr().err == ""


SIGTERM_IN_A_LIBRARY_IMPORT = """
import os, signal, sys, time
from campaign.cli.boundary import run_process

def main():
    try:                                   # a library's import, interrupted by the signal
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    except KeyboardInterrupt as exc:       # what numpy's import_array does: print it, raise its own error
        sys.excepthook(type(exc), exc, exc.__traceback__)
        raise ImportError("numpy._core.multiarray failed to import")
    return 0

run_process(main, lambda text: print(text, file=sys.stderr))
"""


def test_library_error_raised_after_a_signal_exits_130_with_one_line():
    import subprocess

    done = subprocess.run([sys.executable, "-c", SIGTERM_IN_A_LIBRARY_IMPORT], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip().splitlines() == ["terminated by SIGTERM"]


def test_library_error_without_a_signal_still_raises():
    import subprocess

    code = SIGTERM_IN_A_LIBRARY_IMPORT.replace("os.kill(os.getpid(), signal.SIGTERM)", "raise KeyboardInterrupt")
    code = code.replace("time.sleep(5)", "")
    code = code.replace("except KeyboardInterrupt as exc:", "except ZeroDivisionError as exc:")
    code = code.replace("        raise KeyboardInterrupt\n", "        1 / 0\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode != 130 and "ImportError" in done.stderr
