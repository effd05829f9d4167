"""Preflight of the ABB RWS driver: operating mode, motors, mastership, CalServer present, running, its
version and a ping; uploading CalServer when asked (a mixin of ``drivers.abb_rws.AbbRwsRobot``)."""

from __future__ import annotations

import logging
import os
import re

from .base import DriverError, MotionError, RobotError, RobotNotReady
from .rws_client import RwsError
from .rapid import calserver_text
from .abb_rws_program import ENTRY_ROUTINE
from .rapid.literals import parse_num

log = logging.getLogger("drivers.abb_rws")

CALSERVER_VERSION = 2                                          # cal_version expected in CalServer.mod
KIND_PING, KIND_MOVEABSJ, KIND_MOVEL = 0, 1, 2
_IDENT = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")


def module_bytes(name: str, text: str, url: str) -> bytes:
    """Validate a module name/text pair and encode it (ISO-8859-1, as RobotWare reads modules)."""
    if not _IDENT.match(name):
        raise RobotError(f"{url}: {name!r} is not a RAPID module name (letter, then letters/digits/_; max 32)")
    if not re.search(rf"^\s*MODULE\s+{re.escape(name)}\b", text, re.IGNORECASE | re.MULTILINE) \
            or not re.search(r"\bENDMODULE\b", text, re.IGNORECASE):
        raise RobotError(f"{url}: module text must start with 'MODULE {name}' and end with 'ENDMODULE'")
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError as exc:
        raise RobotError(f"{url}: module {name} has characters outside ISO-8859-1 ({exc.reason})") from None


def _read_text(path: str) -> str:
    """A local module file (ISO-8859-1); DriverError if unreadable."""
    try:
        with open(os.path.expanduser(path), encoding="latin-1") as fh:
            return fh.read()
    except OSError as exc:
        raise DriverError(f"abb-rws: options.module_file: cannot read {path}: {exc.strerror}") from None


class PreflightMixin:
    """The checks ``connect`` runs before the first motion (see ``AbbRwsRobot``)."""

    # -- preflight

    def _preflight(self) -> None:
        """AUTO, motors on, no foreign mastership, CalServer present/loaded, RAPID running, CalServer answering."""
        self._check_opmode()
        self._check_motors()
        self._check_track_unit()
        self._check_mastership()
        self._elog_mark = self._newest_elog()
        ident = self.identity()
        log.info("%s: %s %s, serial %s, %s", self.url, ident["controller_type"], ident["model"], ident["serial"],
                 ident["software_version"])
        if ident["absacc"] == "yes":
            log.warning("%s: Absolute Accuracy is installed: joint moves are unaffected, but Cartesian targets "
                        "corrected by this campaign must not be written back (the controller would correct them "
                        "twice)", self.url)
        if self.opts.upload_module:
            self._install_calserver()
        else:
            self._check_module()
        self._check_running()
        self._check_version()
        self._sync_seq()
        self._ping()
        self._write_values(self._motion_arguments())     # cached from here on: a move writes 3 symbols

    def _check_opmode(self) -> None:
        mode = self._opmode()
        if mode != "AUTO":
            raise RobotNotReady(f"{self.url}: controller is in {mode} mode, not AUTO (turn the mode key to AUTO)")

    def _check_track_unit(self) -> None:
        """A track's mechanical unit (``options.track_unit``) must exist and be activated before it is moved."""
        unit = self.opts.track_unit
        if unit is None:
            return
        units = {str(i.get("_title", "")).upper(): i for i in self.session.get(*self._routes.mechunits())}
        mode = str(units.get(unit.upper(), {}).get("mode", "missing"))
        if mode.lower() not in ("activated", "active"):
            raise RobotNotReady(f"{self.url}: mechanical unit {unit} (the track) is {mode.lower()}, not activated "
                                f"(ActUnit {unit} in RAPID or on the FlexPendant)")

    def _check_motors(self) -> None:
        state = self._ctrlstate()
        if state == "motoroff" and self.opts.motors_on:
            path, params = self._routes.set_ctrlstate()
            self.session.post(path, params, {"ctrl-state": "motoron"})
            self._sleep(min(0.5, self.opts.poll_s))
            state = self._ctrlstate()
        if state != "motoron":
            hint = "press Motors On or set options.motors_on" if state == "motoroff" else "reset the stop first"
            raise RobotNotReady(f"{self.url}: motors are not on (ctrlstate={state}; {hint})")

    def _check_mastership(self) -> None:
        for domain in (self._routes.edit_domain, "motion"):
            path, params = self._routes.mastership(domain)
            try:
                items = self.session.get(path, params)
            except RwsError as exc:
                log.info("%s: mastership state %s not readable (%s)", self.url, domain, exc)
                continue
            item = items[0] if items else {}
            holder = str(item.get("mastership", "nomaster")).lower()
            mine = str(item.get("mastershipheldbyme", "false")).lower() == "true"
            if holder not in ("nomaster", "", "internal") and not mine:     # internal: RAPID itself while it runs
                who = item.get("application") or item.get("location") or holder
                raise RobotNotReady(f"{self.url}: {domain} mastership is held by another client ({who}); "
                                    "release write access in RobotStudio / close the FlexPendant editor")

    def _check_module(self) -> None:
        if self.opts.module.lower() not in {m.lower() for m in self._modules()}:
            raise RobotNotReady(f"{self.url}: RAPID module {self.opts.module} is not loaded in {self.opts.task} "
                                "(load drivers/rapid/CalServer.mod or set options.upload_module: true)")

    def _check_running(self) -> None:
        state = self._exec_state()
        if state == "running":
            return
        if not self.opts.start_rapid:
            raise RobotNotReady(f"{self.url}: RAPID execution is {state} (set the PP to routine {ENTRY_ROUTINE} "
                                "and start, or set options.start_rapid: true)")
        self._set_entry_pp()
        self._rapid_start()

    def _check_version(self) -> None:
        try:
            version = parse_num(self._read("cal_version"))
        except RwsError as exc:
            raise RobotNotReady(f"{self.url}: {self.opts.module} has no readable cal_version ({exc.code}); "
                                "upload the module shipped with this driver") from exc
        if int(version) != CALSERVER_VERSION:
            raise RobotNotReady(f"{self.url}: {self.opts.module} interface version {version:g} on the controller, "
                                f"driver needs {CALSERVER_VERSION} (upload the module shipped with this driver)")

    def _sync_seq(self) -> None:
        """Next request number = one above every sequence counter on the controller."""
        names = ("cal_req_seq", "cal_ack_seq", "cal_done_seq", "cal_err_seq")
        self._seq = max(int(parse_num(self._read(n))) for n in names)
        self._written.clear()

    def _ping(self) -> None:
        """A no-motion request proves the CalServer loop answers."""
        try:
            self._command(KIND_PING, {}, "ping", move_s=0.0)
        except MotionError as exc:
            raise RobotNotReady(f"{self.url}: CalServer does not answer ({exc}){self._pp_hint()}") from exc

    def _pp_hint(self) -> str:
        """Where the program pointer is, for a CalServer that does not answer (best effort)."""
        try:
            item = self._first_item(self._routes.pcp(self.opts.task))
        except DriverError:
            return ""
        module, routine = item.get("modulemame") or item.get("modulename"), item.get("routinename")
        if not module or str(routine).lower() == ENTRY_ROUTINE:
            return ""
        return (f"; the program pointer is in {module}/{routine}: run {ENTRY_ROUTINE} (PP to routine, or call "
                f"'{ENTRY_ROUTINE};' from main)")

    def _install_calserver(self) -> None:
        """Upload and verify CalServer, stop RAPID, load it with PP to main, and start RAPID."""
        text = _read_text(self.opts.module_file) if self.opts.module_file else calserver_text()
        data = module_bytes(self.opts.module, text, self.url)
        remote = f"{self.opts.remote_dir}/{self.opts.module}.mod"
        self.session.put_file(remote, data)
        if self.session.get_file(remote) != data:
            raise RobotNotReady(f"{self.url}: read-back of {remote} differs from the uploaded module")
        if self._exec_state() == "running":
            self._rapid_stop_and_wait()
        self._load(remote, reset_pp=False)
        self._check_module()
        self._set_entry_pp()
        self._rapid_start()
        log.info("%s: %s uploaded to %s, loaded into %s and started", self.url, self.opts.module, remote,
                 self.opts.task)
