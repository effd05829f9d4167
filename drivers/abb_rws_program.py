"""RAPID program control for the ABB RWS driver: mastership, program pointer, start/stop, reads and writes of
RAPID data, controller state and event log (a mixin of ``drivers.abb_rws.AbbRwsRobot``)."""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from typing import Callable, Iterator

from .base import DriverError, RobotError, RobotNotReady
from .rws_client import E_MASTER_REJECT, E_RESOURCE_HELD, RwsError, first

log = logging.getLogger("drivers.abb_rws")

ENTRY_ROUTINE = "cal_run"                                      # CalServer's entry procedure (no main of its own)


class Deadline:
    """A point in monotonic time ``seconds`` from now."""

    def __init__(self, seconds: float, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock, self.seconds = clock, seconds
        self.end = clock() + seconds

    def expired(self) -> bool:
        return self._clock() >= self.end


class MasterRejected(RobotError):
    """A write refused for lack of mastership (403 E_MASTER_REJECT): switch to explicit mastership."""


def _newer(seq: int, mark: int | None) -> bool:
    """uint16 sequence comparison with wrap-around."""
    return mark is None or 0 < (seq - mark) % 65536 < 32768


class RapidProgramMixin:
    """Program control and data access over ``self._session`` (see ``AbbRwsRobot``)."""

    # -- RAPID program control

    @contextmanager
    def _edit_mastership(self) -> Iterator[None]:
        """Hold the RAPID-edit mastership (``rapid`` on 1.0, ``edit`` on 2.0) for the block; always release.
        A request refused because another client holds it is retried with backoff (``retry`` options)."""
        domain = self._routes.edit_domain
        delay = self.opts.retry.backoff_s
        for attempt in range(self.opts.retry.retries + 1):
            try:
                self._mastership(domain, "request")
                break
            except RobotNotReady:
                if attempt == self.opts.retry.retries:
                    raise
                log.info("%s: %s mastership held elsewhere; retry %d/%d in %.2f s", self.url, domain, attempt + 1,
                         self.opts.retry.retries, delay)
                self._sleep(delay)
                delay = min(delay * 2, self.opts.retry.backoff_max_s)
        try:
            yield
        finally:
            self._mastership(domain, "release", quiet=True)

    def _set_entry_pp(self) -> None:
        """RAPID stopped: PP to routine ``cal_run`` (restored to main at close) or, with ``entry: main``, PP to
        the task's main (which must call ``cal_run``)."""
        with self._edit_mastership():
            if self.opts.entry == "main":
                self._post_resetpp()
                return
            path, params = self._routes.pp_to_routine(self.opts.task)
            try:
                self.session.post(path, params, {"module": self.opts.module, "routine": ENTRY_ROUTINE,
                                                 "userlevel": "false"})
            except RwsError as exc:
                raise RobotNotReady(f"{self.url}: cannot set the program pointer to {self.opts.module}/"
                                    f"{ENTRY_ROUTINE} ({exc})") from exc
            self._restore_pp = True

    def _load(self, remote: str, *, reset_pp: bool) -> None:
        """``loadmod`` (replace) under edit mastership, optionally followed by PP to main."""
        with self._edit_mastership():
            path, params = self._routes.loadmod(self.opts.task)
            self.session.post(path, params, {"modulepath": remote, "replace": "true"},
                              timeout=self.opts.timeouts.load_s)
            if reset_pp:
                self._post_resetpp()

    def _reset_pp(self) -> None:
        """PP to main (edit mastership is required on RWS 2.0; taken on both)."""
        with self._edit_mastership():
            self._post_resetpp()

    def _post_resetpp(self) -> None:
        path, params = self._routes.execution_action("resetpp")
        self.session.post(path, params, {})

    def _rapid_start(self) -> None:
        """Start RAPID (cycle forever) and wait until the execution state says running."""
        path, params = self._routes.execution_action("start")
        form = {"regain": "continue", "execmode": "continue", "cycle": "forever", "condition": "none",
                "stopatbp": "disabled", "alltaskbytsp": "false"}
        try:
            self.session.post(path, params, form)
        except RwsError as exc:
            raise RobotNotReady(f"{self.url}: RAPID start refused ({exc})") from exc
        self._wait_exec("running")

    def _rapid_stop_and_wait(self) -> None:
        path, params = self._routes.execution_action("stop")
        self.session.post(path, params, {"stopmode": "stop", "usetsp": "normal"})
        self._wait_exec("stopped")

    def _wait_exec(self, wanted: str) -> None:
        deadline = Deadline(self.opts.timeouts.ack_s)
        while self._exec_state() != wanted:
            if deadline.expired():
                raise RobotNotReady(f"{self.url}: RAPID execution did not become {wanted} "
                                    f"within {deadline.seconds:g} s")
            self._sleep(min(self.opts.poll_s, 0.05))

    def _mastership(self, domain: str, verb: str, *, quiet: bool = False) -> None:
        path, params = self._routes.mastership_action(domain, verb)
        try:
            self.session.post(path, params, {})
        except RwsError as exc:
            if quiet:
                log.warning("%s: mastership %s %s failed: %s", self.url, domain, verb, exc)
                return
            if exc.code == E_RESOURCE_HELD:
                raise RobotNotReady(f"{self.url}: {domain} mastership is held by another client") from exc
            raise

    # -- reads and writes

    def _read(self, name: str) -> str:
        """Value literal of a CalServer symbol."""
        path, params = self._routes.symbol(self.opts.task, self.opts.module, name)
        return first(self.session.get(path, params), "value", name)

    def _write(self, name: str, literal: str, *, cache: bool) -> None:
        """Write a CalServer symbol (skipped if this session already wrote the same literal)."""
        if cache and self._written.get(name) == literal:
            return
        path, params = self._routes.set_symbol(self.opts.task, self.opts.module, name, implicit=not self._explicit)
        try:
            self.session.post(path, params, {"value": literal})
        except RwsError as exc:
            self._written.pop(name, None)
            if exc.code == E_MASTER_REJECT and not self._explicit:
                raise MasterRejected(str(exc)) from exc
            if exc.code == E_RESOURCE_HELD:
                raise RobotNotReady(f"{self.url}: cannot write {name}: RAPID mastership held by another client") \
                    from exc
            raise
        self._written[name] = literal

    def _ctrlstate(self) -> str:
        path, params = self._routes.ctrlstate()
        return first(self.session.get(path, params), "ctrlstate", "ctrlstate")

    def _opmode(self) -> str:
        path, params = self._routes.opmode()
        return first(self.session.get(path, params), "opmode", "opmode")

    def _exec_state(self) -> str:
        path, params = self._routes.execution()
        return first(self.session.get(path, params), "ctrlexecstate", "execution")

    def _modules(self) -> list[str]:
        path, params = self._routes.modules(self.opts.task)
        return [str(i.get("name", "")) for i in self.session.get(path, params)]

    def _elog_entries(self) -> list[dict]:
        """Common elog entries (newest first) with int ``seqnum``; empty if the log is not readable."""
        path, params = self._routes.elog()
        try:
            items = self.session.get(path, params)
        except DriverError as exc:
            log.info("%s: event log not readable: %s", self.url, exc)
            return []
        out = []
        for item in items:
            try:
                out.append(dict(item, seqnum=int(str(item.get("_title", "")).rstrip("/").split("/")[-1])))
            except ValueError:
                continue
        return out

    def _newest_elog(self) -> int | None:
        """Newest sequence number in the log (uint16 wrap-aware), or None for an empty/unreadable log."""
        newest = None
        for entry in self._elog_entries():
            if _newer(entry["seqnum"], newest):
                newest = entry["seqnum"]
        return newest

    def _elog_errors(self) -> str:
        """``; elog: code title`` for error entries (msgtype >= 3) newer than the mark; advances the mark."""
        entries = [e for e in self._elog_entries() if _newer(e["seqnum"], self._elog_mark)]
        for entry in entries:
            if _newer(entry["seqnum"], self._elog_mark):
                self._elog_mark = entry["seqnum"]
        errors = [f"{e.get('code', '?')} {e.get('title', '')}".strip() for e in entries
                  if str(e.get("msgtype", "0")).isdigit() and int(e["msgtype"]) >= 3]
        return f"; elog: {'; '.join(errors[:3])}" if errors else ""
