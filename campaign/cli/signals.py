"""SIGTERM, SIGHUP and SIGINT for the CLI: the signal always wins, and is never lost.

* :func:`install` sets one handler for the three signals. While the handlers are *armed* the first signal raises
  :class:`campaign.errors.Terminated` (``KeyboardInterrupt`` for SIGINT) in the main thread, like Ctrl-C; the
  handler disarms itself as it raises, so a second signal cannot interrupt the clean-up the first one started
  (stopping the robot, closing the log, removing a temporary file). Every signal is recorded (:func:`received`).
* A signal that lands inside a finaliser (a ``__del__``, a weakref callback) has its exception dropped by Python
  ("Exception ignored in ..."). The unraisable hook recognises it, prints nothing and has the signal delivered
  again 10 ms later, so that it is raised in ordinary code. Once a signal has arrived, any other exception dropped
  in a finaliser is silenced too: it comes from an object the signal left half-built (seen in a library import).
  Likewise the exception hook: C code that prints an exception (numpy's ``import_array`` when the signal lands in
  the import of one of its modules) prints nothing after a signal, and the console script turns the library's
  own error that follows (an ``ImportError``) into the signal's exit 130.
* The console script (``main()`` without arguments) installs the handlers before anything is imported or printed
  and never restores them: it ends in :func:`exit_process`, which blocks the signals, turns any signal received
  so far into exit 130 and leaves through ``os._exit`` so that no signal can land in interpreter teardown (where
  Python has restored the default handlers). An in-process caller (tests) gets the previous handlers back from
  :func:`restore`, called by plain code, never by a finaliser.

This module imports only the standard library's light modules: it runs before the rest of the CLI is loaded.
"""
from __future__ import annotations

import _thread
import os
import signal
import sys
import threading
from collections.abc import Callable

from campaign.errors import Terminated

REDELIVER_S = 0.01             # delay before a signal dropped in a finaliser is delivered again
SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP", "SIGINT") if hasattr(signal, n))


class _State:
    installed = False
    armed = False
    received: str | None = None          # the first signal's name
    previous: dict = {}
    previous_hook = None
    previous_excepthook = None


_state = _State()


def _handler(signum: int, frame) -> None:
    name = signal.Signals(signum).name
    if _state.received is None:
        _state.received = name
    if _state.armed:
        _state.armed = False
        raise KeyboardInterrupt() if signum == signal.SIGINT else Terminated(name)


def _unraisable(args) -> None:
    """A signal's exception dropped inside a finaliser: say nothing, raise it again in ordinary code (a moment
    later, from a helper thread: raised from here it would be dropped again)."""
    if isinstance(args.exc_value, KeyboardInterrupt) and _state.installed:
        _state.armed = True
        signum = getattr(signal, _state.received or "SIGINT", signal.SIGINT)
        timer = threading.Timer(REDELIVER_S, _thread.interrupt_main, (signum,))
        timer.daemon = True
        timer.start()
        return
    if _state.installed and _state.received is not None:
        # After a signal, a finaliser of an object the signal interrupted half-way through building (a library
        # being imported, say) may fail on its missing attributes: noise, the command ends with exit 130 anyway.
        return
    (_state.previous_hook or sys.__unraisablehook__)(args)


def _excepthook(exc_type, exc_value, exc_traceback) -> None:
    """An exception printed by C code (``PyErr_Print``: numpy's ``import_array`` when a signal interrupts the
    import of one of its modules): silent once a signal has arrived, the command ends with exit 130."""
    if _state.installed and _state.received is not None:
        return
    (_state.previous_excepthook or sys.__excepthook__)(exc_type, exc_value, exc_traceback)


def install() -> bool:
    """Install and arm the handlers (main thread only; False elsewhere, or when they already are)."""
    if _state.installed or threading.current_thread() is not threading.main_thread():
        return False
    _state.received, _state.previous = None, {}
    for sig in SIGNALS:
        try:
            _state.previous[sig] = signal.signal(sig, _handler)
        except (OSError, ValueError):
            pass
    _state.previous_hook, sys.unraisablehook = sys.unraisablehook, _unraisable
    _state.previous_excepthook, sys.excepthook = sys.excepthook, _excepthook
    _state.installed = _state.armed = True
    return True


def disarm() -> None:
    """From now on a signal is only recorded (the command is finishing: its exit code and line are decided)."""
    _state.armed = False


def received() -> str | None:
    """The name of the first signal received since :func:`install` (None: none)."""
    return _state.received


def restore() -> None:
    """Disarm, then put the previous handlers and unraisable hook back (in-process callers)."""
    _state.armed = False
    for sig, old in _state.previous.items():
        signal.signal(sig, old)
    if _state.installed:
        sys.unraisablehook = _state.previous_hook or sys.__unraisablehook__
        sys.excepthook = _state.previous_excepthook or sys.__excepthook__
    _state.installed, _state.previous = False, {}


def block() -> None:
    """Block the signals in this thread (they stay pending); records any that is pending."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
        pending = signal.sigpending() & set(SIGNALS)
        if pending and _state.received is None:
            _state.received = signal.Signals(min(pending)).name


def exit_process(code: int, line: Callable[[str], None] | None) -> None:
    """End the process with ``code``, or 130 if a signal arrived (then ``line(signal name)`` prints the one line,
    unless it is None: the command printed its line); flushes stdout/stderr and leaves through ``os._exit``."""
    _state.armed = False
    block()
    if _state.received is not None:
        code = 130
        if line is not None:
            try:
                line(_state.received)
            except (OSError, ValueError):                  # stderr closed or a broken pipe: the exit code says it
                pass
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
