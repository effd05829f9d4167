"""Localhost emulator of an ABB controller's Robot Web Services: RWS 1.0 (IRC5) or RWS 2.0 (OmniCore).

It implements what ``drivers.abb_rws`` and public RWS clients (``abb_robot_client.rws.RWS`` for RWS 1.0, the RWS 2.0
client ``RWS2`` of the Mesh-ch fork of abb_robot_client) use:

- authentication: real Digest (RFC 7616 / 2617, MD5, ``qop="auth"``, realm ``validusers@robapi.abb``, fresh nonce
  per challenge, stale nonces rejected) on 1.0; Basic on 2.0 (Digest rejected);
- sessions: cookies ``-http-session-`` and ``ABBCX`` set on the first authenticated answer; a valid cookie
  authenticates; a session cap (default 70) answers 503; idle sessions expire; ``GET /logout`` frees the slot
  and the session's mastership;
- representations: 1.0 ``?json=1`` (``_embedded._state``, ``Content-Type: application/json`` exactly) or XHTML;
  2.0 HAL (``state[]`` / ``_embedded.resources[]``) requiring ``Accept: …;v=2.0`` (else 406) and ``;v=2.0``
  request bodies (else 415); error envelopes with RobotWare return codes;
- controller model: operating mode, controller state, RAPID execution state and cycle, the program pointer
  (module, routine), mastership per domain and session (``internal`` for motion while RAPID runs), a task ``T_ROB1``
  whose modules are parsed from uploaded ``.mod`` text (module-level ``PERS``/``VAR``/``CONST`` declarations
  become typed RAPID symbols, procedures and what ``main`` calls are recorded), a production program
  ``MainModule`` (its ``main`` calls ``cal_run`` or not: ``customer_program``), a file service (``$HOME``,
  ``$TEMP``, ``$RAMDISK``), the ROB_1 joint and Cartesian state (also as the task's ``motion/jointtarget`` and
  ``motion/robtarget`` read by RW7 clients), speed ratio, identity (``/ctrl/identity``, robot type, system
  options with or without ``Absolute Accuracy``) and an event log;
- rules: motors on only in AUTO; start only in AUTO with motors on, stopped, PP set, program linked (2.0: caller
  holds no edit mastership); resetpp / PP to routine / loadmod only when stopped and with edit mastership;
  a second ``main`` (or main calling an unknown procedure) loads but does not link, as on a controller: elog
  "Link error" and start / PP moves answer 400 ``-1073442802``; PP to a routine with parameters -> 400
  ``-1073442801``; foreign mastership -> 403 ``-1073445862``; missing mastership (and, with
  ``implicit_mastership=False``, writes with ``mastership=implicit``) -> 403 ``-1073445859``; bad literal -> 400
  ``-1073445879``; unknown symbol -> 1.0 400 ``-1073414146`` / 2.0 404 ``-1073442816``; missing load file -> 400
  ``-1073438708``;
- a thread that plays ``CalServer.mod`` while RAPID runs cal_run (PP at cal_run, or at a main calling it):
  resync on a PP move, ack, ``cal_limit`` (clamp the speed to ``cal_vmax``, VelSet override; recorded with the
  ``cal_tool`` load in ``executed``), move the simulated robot at ``joint_speed_deg_s`` x override (interrupted if
  RAPID stops or motors go off), call the ``move_hook`` (plug the campaign's mock world in here), dwell
  ``cal_settle_s``, set ``cal_reached`` and done; ``cal_state`` mirrors [ack, done, err];
- fault injection: 503 storms, 401 (session expiry) on the next requests, motors off / RAPID stop / RAPID-side
  error / hang on the next move, manual mode, foreign mastership (optionally released after N refusals), extra
  elog entries.

Not implemented: subscriptions / WebSockets, IO signals, RMMP, configuration, XHTML on RWS 2.0 beyond the basics.

RWS 2.0 is served over HTTPS with a throwaway self-signed certificate when the ``cryptography`` package is
installed (``tls=None``, the default); otherwise, or with ``tls=False`` / ``--http``, over plain HTTP on loopback.
The server binds to loopback only. Elog codes produced by faults are illustrative.

Run: ``python -m drivers.emulators.rws_server --version 1 --port 0 --print-port``; in-process:
``with RwsEmulator(version=2) as emu: open_robot(emu.url, {...})``.
"""
from __future__ import annotations

import argparse
import ipaddress
import logging
import os
import re
import secrets
import signal
import ssl
import sys
import tempfile
import threading
from datetime import datetime
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Callable, Sequence
from urllib.parse import urlsplit

from drivers.rapid import calserver_text
from drivers.rapid.values import (SHAPES, Module, RapidSyntaxError, Symbol, matches, parse_literal,  # noqa: F401
                                  parse_module, render)

from .rws_auth import AuthMixin
from .rws_calserver import CalServerMixin
from .rws_controller import ControllerMixin
from .rws_faults import FaultsMixin
from .rws_http import (CUSTOMER_PROGRAMS, DEFAULT_LIMITS_DEG, ENTRY, UNRESOLVED_URL, UNUSED, EmulatedMotionFault,  # noqa: F401
                       Request, Response, Fault, Holder, Reject, Session)

log = logging.getLogger(__name__)


class RwsEmulator(FaultsMixin, AuthMixin, ControllerMixin, CalServerMixin):
    """An in-process RWS server on 127.0.0.1 (see the module docstring). Use as a context manager."""

    def __init__(self, version: int = 1, *, host: str = "127.0.0.1", port: int = 0, tls: bool | None = None,
                 user: str = "Default User", password: str = "robotics", max_sessions: int = 70,
                 session_idle_s: float = 300.0, preload_calserver: bool = True, rapid_running: bool = True,
                 joint_speed_deg_s: float = 200.0, q0_deg: Sequence[float] = (0, 0, 0, 0, 30, 0),
                 joint_limits_deg: Sequence[tuple[float, float]] = DEFAULT_LIMITS_DEG,
                 move_hook: Callable[[tuple[float, ...]], Sequence[float] | None] | None = None,
                 robtarget_hook: Callable[[tuple[float, ...], tuple[float, ...], tuple[int, ...]],
                                          Sequence[float] | None] | None = None,
                 customer_program: str | None = "auto", implicit_mastership: bool = True,
                 serial: str = "2600-104512", robot_type: str = "IRB 2600-12/1.65", absacc: bool = False,
                 ext_q0: Sequence[float] = (), units: Sequence[str] = ()) -> None:
        if version not in (1, 2):
            raise ValueError("version must be 1 or 2")
        if not ipaddress.ip_address(host).is_loopback:
            raise ValueError(f"the emulator binds to loopback only, not {host}")
        self.version, self.host, self._port = version, host, port
        self.tls = (version == 2 and _have_cryptography()) if tls is None else bool(tls)
        self._user, self._password = user, password
        self.max_sessions, self.session_idle_s = max_sessions, session_idle_s
        self.joint_speed_deg_s, self.joint_limits = joint_speed_deg_s, [tuple(x) for x in joint_limits_deg]
        self.move_hook, self.robtarget_hook = move_hook, robtarget_hook
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._halt = threading.Event()
        self._opaque = secrets.token_hex(8)
        self._nonces: dict[str, float] = {}
        self._sessions: dict[str, Session] = {}
        self._fail_503 = 0
        self._fail_401 = 0
        self._faults: list[Fault] = []
        self.calserver_alive = True    # False: RAPID runs but the loop never takes requests (stuck elsewhere)
        # controller model
        self.opmode, self.ctrlstate, self.speedratio = "AUTO", "motoron", 100
        self.execution, self.cycle, self._fresh_start = "stopped", "forever", True
        self.pp: tuple[str, str] | None = None       # (module, routine) of the program pointer
        self.implicit_mastership = implicit_mastership
        self.serial, self.robot_type = serial, robot_type
        self.system_options = ["RobotWare Base", "English", "PC Interface" if version == 1 else "Robot Web Services",
                               "Multitasking"] + (["Absolute Accuracy"] if absacc else [])
        self.executed: list[dict] = []    # per served motion request: what the simulated RAPID did (speeds, load)
        self._foreign_refusals: dict[str, int] = {}
        self.mastership: dict[str, Holder] = {}
        self.modules: dict[str, Module] = {}
        self.files: dict[str, bytes] = {}
        self.elog: list[dict] = []
        self._elog_seq = 100
        self.joints = [float(v) for v in q0_deg] + [0.0] * (6 - len(q0_deg))
        self.ext = [float(v) for v in ext_q0] + [UNUSED] * (6 - len(ext_q0))    # eax_a.. (a track, YuMi's axis 7)
        self.units = {str(u): "Activated" for u in units}     # extra mechanical units (a track: its axis is eax_a)
        self.robtarget = ([600.0, 0.0, 800.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 0])
        self.robtarget_ext = [UNUSED] * 6             # its external axes (a YuMi's arm angle, a track: eax_a)
        self.moves: list[tuple[str, tuple[float, ...]]] = []
        self.requests: list[tuple[str, str, str, int]] = []   # method, path, query, status
        self.counts = {"logouts": 0, "sessions": 0, "auth_failures": 0}
        if customer_program == "auto":
            customer_program = "calls" if preload_calserver else "plain"
        if customer_program is not None:
            self._install(parse_module(CUSTOMER_PROGRAMS[customer_program]))
        if preload_calserver:
            self._install(parse_module(calserver_text()))
        main = next((m.name for m in self.modules.values() if m.has_main), None)
        self.pp = (main, "main") if main else ("CalServer", ENTRY) if preload_calserver else None
        self.add_elog(1, 10011, "Motors ON state")
        if rapid_running and preload_calserver and self._pp_reaches_calserver():
            self.execution = "running"
            self.add_elog(1, 10151, "Program started")
        self._server: ThreadingHTTPServer | None = None
        self._threads: list[threading.Thread] = []
        self._tmpdir: tempfile.TemporaryDirectory | None = None
        self.cert_path: str | None = None

    # -- lifecycle

    def start(self) -> "RwsEmulator":
        """Bind, serve in a thread and start the simulated CalServer loop."""
        ctx = self._ssl_context() if self.tls else None
        self._server = _Server((self.host, self._port), _Handler, self, ctx)
        self._threads = [threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                          name="rws-emulator-http", daemon=True),
                         threading.Thread(target=self._calserver_loop, name="rws-emulator-calserver", daemon=True)]
        for t in self._threads:
            t.start()
        return self

    def stop(self) -> None:
        """Stop serving and the simulated loop."""
        self._halt.set()
        self._wake.set()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
        for t in self._threads:
            t.join(timeout=2)
        self._threads = []
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None

    def __enter__(self) -> "RwsEmulator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def port(self) -> int:
        return self._server.server_address[1] if self._server else self._port

    @property
    def scheme(self) -> str:
        return "https" if self.tls else "http"

    @property
    def base_url(self) -> str:
        """``http(s)://127.0.0.1:PORT`` (for third-party clients)."""
        return f"{self.scheme}://{self.host}:{self.port}"

    @property
    def url(self) -> str:
        """``abb-rws://127.0.0.1:PORT`` (for the driver registry)."""
        return f"abb-rws://{self.host}:{self.port}"

    def _ssl_context(self) -> ssl.SSLContext:
        self._tmpdir = tempfile.TemporaryDirectory(prefix="rws-emulator-")
        cert, key = _self_signed_cert(Path(self._tmpdir.name), self.host)
        self.cert_path = cert                   # the self-signed certificate (PEM), for clients that verify
        ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        ctx.load_cert_chain(cert, key)
        return ctx

    # -- observation

    def symbol(self, name: str, module: str = "CalServer") -> str:
        """Rendered value of a module symbol."""
        with self._lock:
            return self.modules[module.lower()].symbols[name.lower()].value

    def set_symbol(self, name: str, literal: str, module: str = "CalServer") -> None:
        with self._lock:
            sym = self.modules[module.lower()].symbols[name.lower()]
            sym.value = render(parse_literal(literal))
        self._wake.set()

    @property
    def session_count(self) -> int:
        with self._lock:
            return len(self._sessions)

    def count(self, method: str, path: str, contains: str = "") -> int:
        """Number of requests seen with this method and path (and ``contains`` in the query string)."""
        with self._lock:
            return sum(1 for m, p, q, _ in self.requests if m == method and p == path and contains in q)

    # -- request dispatch

    def dispatch(self, req: Request) -> Response:
        """Answer one request (thread-safe)."""
        with self._lock:
            resp = self._dispatch(req)
            self.requests.append((req.method, req.path, urlsplit(req.target).query, resp.status))
        self._wake.set()
        return resp

    def _dispatch(self, req: Request) -> Response:
        if self._fail_503 > 0:
            self._fail_503 -= 1
            return Response(503, b"Service Unavailable", [("Content-Type", "text/plain")])
        session, cookies, denied = self._authenticate(req)
        if denied is not None:
            return denied
        bad = self._check_media(req)
        if bad is not None:
            return bad
        try:
            resp = self._route(req, session)
        except Reject as rej:
            resp = self._error(req, rej.status, rej.code, rej.detail)
        resp.headers.extend(("Set-Cookie", c) for c in cookies)
        return resp

    # -- routing

    def _route(self, req: Request, session: Session) -> Response:
        path = req.path.rstrip("/") or "/"
        for method, pattern, handler in self._table():
            m = re.fullmatch(pattern, path)
            if m and method == req.method:
                return handler(req, session, *m.groups())
        if any(re.fullmatch(p, path) for _, p, _ in self._table()):
            return Response(405, b"", [("Content-Type", "text/plain")])
        raise Reject(404, UNRESOLVED_URL, path)

    def _table(self) -> list[tuple[str, str, Callable[..., Response]]]:
        common = [
            ("GET", r"/", self._get_root), ("GET", r"/logout", self._logout), ("GET", r"/rw/system", self._system),
            ("GET", r"/rw/panel/opmode", self._get_opmode), ("GET", r"/rw/panel/speedratio", self._get_speedratio),
            ("POST", r"/rw/panel/speedratio", self._set_speedratio), ("GET", r"/rw/rapid/execution", self._get_exec),
            ("GET", r"/rw/rapid/tasks", self._get_tasks), ("GET", r"/rw/mastership/(\w+)", self._get_mastership),
            ("GET", r"/rw/motionsystem/mechunits", self._get_mechunits),
            ("GET", r"/rw/motionsystem/mechunits/(\w+)/jointtarget", self._get_jointtarget),
            ("GET", r"/rw/motionsystem/mechunits/(\w+)/robtarget", self._get_robtarget),
            ("GET", r"/rw/elog/(\d+)", self._get_elog), ("GET", r"/ctrl/identity", self._get_identity),
            ("GET", r"/rw/system/robottype", self._get_robottype), ("GET", r"/rw/system/options", self._get_options),
            ("GET", r"/rw/rapid/tasks/(\w+)/pcp", self._get_pcp), ("GET", r"/ctrl/(\$?\w+)", self._get_ctrl_var),
            ("GET", r"/fileservice/(.+)", self._get_file), ("PUT", r"/fileservice/(.+)", self._put_file),
            ("DELETE", r"/fileservice/(.+)", self._delete_file), ("HEAD", r"/fileservice/(.+)", self._head_file),
        ]
        if self.version == 1:
            return common + [
                ("GET", r"/rw/panel/ctrlstate", self._get_ctrlstate),
                ("POST", r"/rw/panel/ctrlstate", self._post1_ctrl),
                ("POST", r"/rw/rapid/execution", self._post1_exec), ("GET", r"/rw/rapid/modules", self._get_modules1),
                ("POST", r"/rw/rapid/tasks/(\w+)", self._post1_task),
                ("POST", r"/rw/rapid/tasks/(\w+)/pcp", self._post1_pcp),
                ("GET", r"/rw/rapid/tasks/(\w+)/motion", self._get_task_motion1),
                ("GET", r"/rw/rapid/symbol/data/RAPID/(\w+)/(\w+)(?:/(\w+))?", self._get_symbol),
                ("POST", r"/rw/rapid/symbol/data/RAPID/(\w+)/(\w+)(?:/(\w+))?", self._post1_symbol),
                ("POST", r"/rw/mastership(?:/(\w+))?", self._post1_mastership),
            ]
        return common + [
            ("GET", r"/rw/panel/ctrl-state", self._get_ctrlstate), ("POST", r"/rw/panel/ctrl-state", self._set_ctrl),
            ("POST", r"/rw/rapid/execution/(start|stop|resetpp)", self._post2_exec),
            ("GET", r"/rw/rapid/tasks/(\w+)/modules", self._get_modules2),
            ("POST", r"/rw/rapid/tasks/(\w+)/(loadmod|unloadmod)", self._post2_task),
            ("POST", r"/rw/rapid/tasks/(\w+)/pcp/routine", self._post2_pcp),
            ("GET", r"/rw/rapid/tasks/(\w+)/motion/(jointtarget|robtarget)", self._get_task_motion2),
            ("GET", r"/rw/rapid/symbol/RAPID/(\w+)/(\w+)(?:/(\w+))?/data", self._get_symbol),
            ("POST", r"/rw/rapid/symbol/RAPID/(\w+)/(\w+)(?:/(\w+))?/data", self._post2_symbol),
            ("POST", r"/rw/mastership(?:/(\w+))?/(request|release)", self._post2_mastership),
        ]


# --------------------------------------------------------------------------- TLS and the socket server


def _have_cryptography() -> bool:
    try:
        import cryptography  # noqa: F401
    except ImportError:
        return False
    return True


def _self_signed_cert(folder: Path, host: str) -> tuple[str, str]:
    """A throwaway EC P-256 certificate for ``host`` (1 day), like OmniCore's self-signed one."""
    from datetime import timedelta, timezone

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "rws-emulator")])
    now = datetime.now(timezone.utc)
    san = x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address(host)), x509.DNSName("localhost")])
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - timedelta(minutes=5))
            .not_valid_after(now + timedelta(days=1)).add_extension(san, critical=False)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    os.chmod(key_path, 0o600)
    return str(cert_path), str(key_path)


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False

    def __init__(self, address: tuple[str, int], handler: type, emu: RwsEmulator,
                 ssl_context: ssl.SSLContext | None) -> None:
        self.emu, self.ssl_context = emu, ssl_context
        super().__init__(address, handler)

    def finish_request(self, request: Any, client_address: Any) -> None:
        """TLS handshake in the worker thread, so a silent client cannot block the accept loop."""
        if self.ssl_context is None:
            return super().finish_request(request, client_address)
        request.settimeout(5)
        try:
            tls = self.ssl_context.wrap_socket(request, server_side=True)
        except (ssl.SSLError, OSError):
            return None
        try:
            super().finish_request(tls, client_address)
        finally:
            tls.close()


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    timeout = 30
    wbufsize = 1 << 16               # headers and body leave in one segment (no Nagle / delayed-ACK stalls)
    disable_nagle_algorithm = True
    server: _Server

    def _handle(self) -> None:
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else b""
        resp = self.server.emu.dispatch(Request(self.command, self.path, self.headers, body))
        self.send_response(resp.status)
        for key, value in resp.headers:
            self.send_header(key, value)
        if resp.status not in (204, 304):
            self.send_header("Content-Length", str(len(resp.body)))
        self.end_headers()
        if self.command != "HEAD" and resp.body:
            self.wfile.write(resp.body)

    do_GET = do_POST = do_PUT = do_DELETE = do_HEAD = _handle

    def log_message(self, fmt: str, *args: Any) -> None:
        log.debug("%s " + fmt, self.address_string(), *args)


# --------------------------------------------------------------------------- CLI


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m drivers.emulators.rws_server --version 1|2 [--port 0] [--print-port]``: serve until ^C."""
    p = argparse.ArgumentParser(description="ABB Robot Web Services emulator (loopback only)")
    p.add_argument("--version", type=int, choices=(1, 2), default=1, help="RWS 1.0 (IRC5) or 2.0 (OmniCore)")
    p.add_argument("--host", default="127.0.0.1", help="loopback address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=0, help="TCP port (0 = a free one)")
    p.add_argument("--print-port", action="store_true", help="print the bound port on stdout")
    p.add_argument("--http", action="store_true", help="serve RWS 2.0 over plain HTTP")
    p.add_argument("--user", default="Default User")
    p.add_argument("--password-env", default="RWS_PASSWORD",
                   help="environment variable holding the password (default RWS_PASSWORD, else 'robotics')")
    p.add_argument("--joint-speed", type=float, default=200.0, help="simulated joint speed (deg/s)")
    p.add_argument("--robot-type", default="IRB 2600-12/1.65", help="robot type the controller reports")
    p.add_argument("--serial", default="2600-104512", help="controller serial number (ctrl-id)")
    a = p.parse_args(argv)
    emu = RwsEmulator(a.version, host=a.host, port=a.port, tls=False if a.http else None, user=a.user,
                      password=os.environ.get(a.password_env, "robotics"), joint_speed_deg_s=a.joint_speed,
                      robot_type=a.robot_type, serial=a.serial)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with emu:
        if a.print_port:
            print(emu.port, flush=True)
        print(f"RWS {a.version}.0 emulator on {emu.base_url} (user {a.user!r})", file=sys.stderr, flush=True)
        try:
            while not stop.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
