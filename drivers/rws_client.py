"""HTTP session layer for ABB Robot Web Services: RWS 1.0 (IRC5, RobotWare 6) and RWS 2.0 (OmniCore, RobotWare 7).

One ``RwsSession`` is one ``httpx.Client``, i.e. one cookie session on the controller for the whole campaign
(re-creating sessions fills the controller's session pool and ends in HTTP 503). The session:

- detects the flavour from the unauthenticated ``GET /`` challenge (``Digest`` -> 1.0, ``Basic`` -> 2.0);
- speaks the flavour's URL grammar (``Routes``), representation (``?json=1`` / ``application/hal+json;v=2.0``)
  and content types (``;v=2.0`` on RWS 2.0 bodies);
- retries 503 (session pool full / busy) with bounded exponential backoff, keeping its cookies;
- re-authenticates once on 401 (session expired) and retries the request;
- sends a cheap GET first when idle for longer than ``heartbeat_s`` (opportunistic heartbeat, no thread);
- translates every httpx exception into a ``DriverError`` subclass at this boundary.

Passwords live only in the httpx auth object; they never appear in messages, reprs or logs.
All times are seconds.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping
from urllib.parse import quote, urlencode

import httpx

from .base import ConnectionLost, DriverError, RobotError

log = logging.getLogger(__name__)

REALM = "validusers@robapi.abb"
HAL_JSON_V2 = "application/hal+json;v=2.0"
FORM_V2 = "application/x-www-form-urlencoded;v=2.0"
FILE_V2 = "text/plain;v=2.0"

# The RobotWare return codes the driver reacts to or reports (names as in ABB's RWS return-code list).
RETCODE_NAMES = {
    294912: "S_OK", -1073445879: "E_INVALIDARG", -1073445867: "E_UAS_REJECT", -1073445866: "E_UNRESOLVED_URL",
    -1073445862: "E_RESOURCE_HELD", -1073445860: "E_MODE_REJECT", -1073445859: "E_MASTER_REJECT",
    -1073445881: "E_REJECT", -1073445872: "E_RESOURCE_ALREADY_HELD", -1073442816: "E_NO_SUCH_SYMBOL",
    -1073442814: "E_INVALID_PROGRAMFILE", -1073442813: "E_MOD_AMBNAME", -1073442809: "E_EXEC_STATE",
    -1073442803: "E_RAPID_SYNTAX_ERROR", -1073442802: "E_RAPID_SEMANTIC_ERROR", -1073442801: "E_ILLEGAL_ENTRYPOINT",
    -1073442783: "E_NO_PP", -1073438716: "E_INVALID_PATH",
    -1073438713: "E_DIR_NOT_EXIST", -1073438708: "E_FILE_NOT_FOUND", -1073414146: "E_FAIL",
}
E_RESOURCE_HELD = -1073445862
E_MASTER_REJECT = -1073445859


class RwsError(RobotError):
    """The controller answered a request with an error status; ``status`` (HTTP) and ``code`` (RWS return code)."""

    def __init__(self, message: str, *, status: int, code: int | None = None) -> None:
        super().__init__(message)
        self.status, self.code = status, code


class RwsAuthError(DriverError):
    """The controller rejected the credentials (HTTP 401 after a fresh authentication)."""


class RwsBusy(ConnectionLost):
    """HTTP 503 persisted through every retry (session pool exhausted or controller busy)."""


@dataclass(frozen=True)
class Timeouts:
    """Per-phase limits (s): TCP/TLS connect, one ordinary request, file upload / module load, the
    CalServer acknowledging a request, and one move from request to done (settle time is added)."""
    connect_s: float = 5.0
    request_s: float = 10.0
    load_s: float = 30.0
    ack_s: float = 5.0
    move_s: float = 120.0


@dataclass(frozen=True)
class RetryPolicy:
    """503 handling: ``retries`` further attempts, sleeping ``backoff_s * 2**i`` capped at ``backoff_max_s``;
    a heartbeat GET precedes any request made after ``heartbeat_s`` of silence."""
    retries: int = 5
    backoff_s: float = 0.5
    backoff_max_s: float = 8.0
    heartbeat_s: float = 30.0


class Credentials:
    """User name and password; the password is never shown by ``repr``/``str``."""

    __slots__ = ("user", "_password")

    def __init__(self, user: str, password: str) -> None:
        self.user, self._password = user, password

    @property
    def password(self) -> str:
        return self._password

    def __repr__(self) -> str:
        return f"Credentials(user={self.user!r}, password=***)"

    __str__ = __repr__


# --------------------------------------------------------------------------- URL grammar


class Routes:
    """The RWS URL grammar of one flavour (``version`` 1 or 2): each method returns ``(path, params)``."""

    def __init__(self, version: int) -> None:
        if version not in (1, 2):
            raise ValueError(f"RWS version must be 1 or 2, got {version!r}")
        self.version = version

    @property
    def edit_domain(self) -> str:
        """Mastership domain guarding RAPID edits: ``rapid`` (1.0) or ``edit`` (2.0)."""
        return "rapid" if self.version == 1 else "edit"

    def ctrlstate(self) -> tuple[str, dict]:
        return ("/rw/panel/ctrlstate" if self.version == 1 else "/rw/panel/ctrl-state"), {}

    def set_ctrlstate(self) -> tuple[str, dict]:
        if self.version == 1:
            return "/rw/panel/ctrlstate", {"action": "setctrlstate"}
        return "/rw/panel/ctrl-state", {}

    def opmode(self) -> tuple[str, dict]:
        return "/rw/panel/opmode", {}

    def execution(self) -> tuple[str, dict]:
        return "/rw/rapid/execution", {}

    def execution_action(self, verb: str) -> tuple[str, dict]:
        """``verb`` in start, stop, resetpp."""
        if self.version == 1:
            return "/rw/rapid/execution", {"action": verb}
        return f"/rw/rapid/execution/{verb}", {}

    def mastership(self, domain: str) -> tuple[str, dict]:
        return f"/rw/mastership/{domain}", {}

    def mastership_action(self, domain: str, verb: str) -> tuple[str, dict]:
        """``verb`` in request, release."""
        if self.version == 1:
            return f"/rw/mastership/{domain}", {"action": verb}
        return f"/rw/mastership/{domain}/{verb}", {}

    def symbol(self, task: str, module: str, name: str) -> tuple[str, dict]:
        """Read a RAPID symbol's value."""
        if self.version == 1:
            return f"/rw/rapid/symbol/data/RAPID/{task}/{module}/{name}", {}
        return f"/rw/rapid/symbol/RAPID/{task}/{module}/{name}/data", {}

    def set_symbol(self, task: str, module: str, name: str, *, implicit: bool = True) -> tuple[str, dict]:
        """Write a RAPID symbol (1.0: implicit when nobody holds RAPID mastership; 2.0: ``mastership=implicit``
        unless ``implicit`` is False, i.e. the caller holds edit mastership explicitly)."""
        if self.version == 1:
            return f"/rw/rapid/symbol/data/RAPID/{task}/{module}/{name}", {"action": "set"}
        return f"/rw/rapid/symbol/RAPID/{task}/{module}/{name}/data", {"mastership": "implicit"} if implicit else {}

    def pp_to_routine(self, task: str) -> tuple[str, dict]:
        """Set the program pointer to a routine (form ``module``, ``routine``, ``userlevel``)."""
        if self.version == 1:
            return f"/rw/rapid/tasks/{task}/pcp", {"action": "set-pp-routine"}
        return f"/rw/rapid/tasks/{task}/pcp/routine", {}

    def pcp(self, task: str) -> tuple[str, dict]:
        """Where the program pointer is (``modulemame``/``routinename``)."""
        return f"/rw/rapid/tasks/{task}/pcp", {}

    def speedratio(self) -> tuple[str, dict]:
        return "/rw/panel/speedratio", {}

    def identity(self) -> tuple[str, dict]:
        return "/ctrl/identity", {}

    def robottype(self) -> tuple[str, dict]:
        return "/rw/system/robottype", {}

    def system_options(self) -> tuple[str, dict]:
        return "/rw/system/options", {}

    def jointtarget(self, mechunit: str) -> tuple[str, dict]:
        return f"/rw/motionsystem/mechunits/{mechunit}/jointtarget", {}

    def mechunits(self) -> tuple[str, dict]:
        return "/rw/motionsystem/mechunits", {}

    def modules(self, task: str) -> tuple[str, dict]:
        if self.version == 1:
            return "/rw/rapid/modules", {"task": task}
        return f"/rw/rapid/tasks/{task}/modules", {}

    def loadmod(self, task: str) -> tuple[str, dict]:
        if self.version == 1:
            return f"/rw/rapid/tasks/{task}", {"action": "loadmod"}
        return f"/rw/rapid/tasks/{task}/loadmod", {}

    def elog(self, limit: int = 50) -> tuple[str, dict]:
        """Common event log (domain 0), newest first."""
        if self.version == 1:
            return "/rw/elog/0", {"lang": "en"}
        return "/rw/elog/0", {"lang": "en", "start": "1", "limit": str(limit)}

    def file(self, controller_path: str) -> tuple[str, dict]:
        """File service path; ``$HOME/x.mod`` keeps a literal ``$`` (RWS 1.0 rejects ``%24HOME``)."""
        return "/fileservice/" + quote(controller_path.lstrip("/"), safe="/$"), {}

    def logout(self) -> tuple[str, dict]:
        return "/logout", {}


# --------------------------------------------------------------------------- envelopes


def state_items(doc: Any, version: int) -> list[dict]:
    """The resource items of a JSON answer: 1.0 ``_embedded._state``; 2.0 ``state`` or ``_embedded.resources``."""
    if not isinstance(doc, dict):
        return []
    embedded = doc.get("_embedded") if isinstance(doc.get("_embedded"), dict) else {}
    if version == 1:
        items = embedded.get("_state", [])
    else:
        items = doc.get("state") or embedded.get("resources", [])
    return [i for i in items if isinstance(i, dict)]


def error_status(doc: Any) -> tuple[int | None, str]:
    """(code, msg) of an error envelope (1.0 ``_embedded.status``, 2.0 ``status``), or (None, "")."""
    if not isinstance(doc, dict):
        return None, ""
    status = doc.get("status") or (doc.get("_embedded") or {}).get("status") or {}
    try:
        code = int(status["code"]) if "code" in status else None
    except (TypeError, ValueError):
        code = None
    return code, str(status.get("msg", ""))


def first(items: list[dict], field: str, what: str) -> str:
    """``items[0][field]`` as a string, or a DriverError naming ``what`` was malformed."""
    if not items or field not in items[0]:
        raise DriverError(f"unexpected RWS answer for {what}: no {field!r} field")
    return str(items[0][field])


def _short(msg: str, limit: int = 160) -> str:
    """One line of at most ``limit`` characters."""
    msg = " ".join(msg.split())
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


# --------------------------------------------------------------------------- session


class RwsSession:
    """One authenticated cookie session with an RWS server (see the module docstring)."""

    def __init__(self, name: str, hostport: str, credentials: Credentials, *, version: int | None = None,
                 scheme: str | None = None, verify: Any = False, timeouts: Timeouts = Timeouts(),
                 policy: RetryPolicy = RetryPolicy(), transport: httpx.BaseTransport | None = None,
                 sleep: Callable[[float], None] = time.sleep, clock: Callable[[], float] = time.monotonic) -> None:
        self.name, self.hostport = name, hostport
        self._credentials = credentials
        self._forced_version, self._forced_scheme = version, scheme
        self.timeouts, self.policy = timeouts, policy
        self._sleep, self._clock = sleep, clock
        self._verify, self._transport = verify, transport
        self.client: httpx.Client | None = None
        self.routes: Routes | None = None
        self._auth: httpx.Auth | None = None
        self._last_ok = 0.0
        self.logged_out = False

    # -- lifecycle

    @property
    def version(self) -> int:
        if self.routes is None:
            raise DriverError(f"{self.name}: RWS session is not open")
        return self.routes.version

    def open(self) -> int:
        """Create the client, detect the flavour and authenticate (``GET /rw/system``); return 1 or 2."""
        self.logged_out = False
        self.client = httpx.Client(verify=self._verify, transport=self._transport, follow_redirects=False,
                                   timeout=self._httpx_timeout(self.timeouts.request_s))
        version = self._detect()
        self.routes = Routes(version)
        self._auth = self._new_auth()
        if version == 2:
            self.client.headers["Accept"] = HAL_JSON_V2
        self._last_ok = self._clock()
        items = self.get("/rw/system")
        rw = items[0].get("rwversion", "?") if items else "?"
        log.info("%s: RWS %d.0 session open (RobotWare %s, %s)", self.name, version, rw, self.client.base_url)
        return version

    def close(self) -> None:
        """Log out (``GET /logout``, frees the controller's session slot) and close the client; never raises."""
        if self.client is None:
            return
        try:
            if self.routes is not None and not self.logged_out:
                path, params = self.routes.logout()
                self._request("GET", path, params=params, expect=(200, 204), timeout=self.timeouts.connect_s)
                self.logged_out = True
        except DriverError as exc:
            log.warning("%s: logout failed: %s", self.name, exc)
        finally:
            self.client.close()
            self.client = None

    # -- flavour detection

    def _schemes(self) -> list[str]:
        """Candidate URL schemes in probing order."""
        if self._forced_scheme:
            return [self._forced_scheme]
        if self._forced_version == 2 or self.hostport.endswith(":443") or ":" not in self.hostport:
            return ["https", "http"] if self._forced_version != 1 else ["http", "https"]
        return ["http", "https"]

    def _detect(self) -> int:
        """Probe ``GET /`` on each candidate scheme; pick the flavour from the auth challenge."""
        failures = []
        for scheme in self._schemes():
            self.client.base_url = f"{scheme}://{self.hostport}"
            try:
                resp = self._send("GET", "/", params={}, auth=None, timeout=self.timeouts.connect_s)
            except RwsBusy:
                raise
            except ConnectionLost as exc:
                failures.append(f"{scheme}: {exc.__cause__ or exc}")
                continue
            version = self._version_from(resp)
            if version is not None:
                return version
            failures.append(f"{scheme}: HTTP {resp.status_code} without an RWS challenge")
        raise ConnectionLost(f"{self.name}: no RWS server found ({'; '.join(_short(f, 120) for f in failures)})")

    def _version_from(self, resp: httpx.Response) -> int | None:
        """1 for a Digest challenge, 2 for Basic; the forced version if given and consistent."""
        challenge = resp.headers.get("www-authenticate", "").strip().lower()
        seen = 1 if challenge.startswith("digest") else 2 if challenge.startswith("basic") else None
        if self._forced_version and seen and seen != self._forced_version:
            raise DriverError(f"{self.name}: rws_version {self._forced_version} was forced but the controller "
                              f"speaks RWS {seen}.0 ({challenge.split(' ')[0].title()} authentication)")
        return self._forced_version or seen

    def _new_auth(self) -> httpx.Auth:
        """Digest (1.0) or Basic (2.0) auth carrying the credentials."""
        cls = httpx.DigestAuth if self.version == 1 else httpx.BasicAuth
        return cls(self._credentials.user, self._credentials.password)

    def _httpx_timeout(self, read_s: float) -> httpx.Timeout:
        return httpx.Timeout(read_s, connect=self.timeouts.connect_s)

    # -- public request helpers

    def get(self, path: str, params: Mapping[str, str] | None = None, *, timeout: float | None = None) -> list[dict]:
        """GET a resource and return its items (see ``state_items``)."""
        resp = self.request("GET", path, params=params, expect=(200,), timeout=timeout)
        return state_items(self._json(resp, path), self.version)

    def post(self, path: str, params: Mapping[str, str] | None = None, form: Mapping[str, str] | None = None, *,
             expect: Iterable[int] = (200, 201, 202, 204), timeout: float | None = None) -> httpx.Response:
        """POST a form-encoded body (``;v=2.0`` content type on RWS 2.0)."""
        ctype = FORM_V2 if self.version == 2 else "application/x-www-form-urlencoded"
        body = urlencode(dict(form or {})).encode()
        return self.request("POST", path, params=params, content=body, headers={"Content-Type": ctype},
                            expect=tuple(expect), timeout=timeout)

    def put_file(self, controller_path: str, data: bytes, *, timeout: float | None = None) -> None:
        """Upload ``data`` to ``controller_path`` (e.g. ``$HOME/CalServer.mod``)."""
        path, _ = self.routes.file(controller_path)
        headers = {"Content-Type": FILE_V2} if self.version == 2 else {}
        self.request("PUT", path, content=data, headers=headers, expect=(200, 201, 204), raw=True,
                     timeout=timeout or self.timeouts.load_s)

    def get_file(self, controller_path: str, *, timeout: float | None = None) -> bytes:
        """Download ``controller_path`` as bytes."""
        path, _ = self.routes.file(controller_path)
        return self.request("GET", path, expect=(200,), raw=True, timeout=timeout or self.timeouts.load_s).content

    def heartbeat(self) -> None:
        """Cheap authenticated GET (controller state) that keeps the session alive."""
        path, params = self.routes.ctrlstate()
        self._request("GET", path, params=params, expect=(200,), timeout=self.timeouts.request_s)

    def request(self, method: str, path: str, *, params: Mapping[str, str] | None = None, content: bytes | None = None,
                headers: Mapping[str, str] | None = None, expect: Iterable[int] = (200,), raw: bool = False,
                timeout: float | None = None) -> httpx.Response:
        """One RWS request with heartbeat, 503 backoff, 401 re-authentication and typed errors."""
        if self.client is None or self.routes is None:
            raise DriverError(f"{self.name}: RWS session is not open (call connect() first)")
        if self._clock() - self._last_ok > self.policy.heartbeat_s:
            log.debug("%s: idle for more than %.0f s, heartbeat first", self.name, self.policy.heartbeat_s)
            self.heartbeat()
        return self._request(method, path, params=params, content=content, headers=headers, expect=expect,
                             raw=raw, timeout=timeout)

    # -- internals

    def _request(self, method: str, path: str, *, params: Mapping[str, str] | None = None,
                 content: bytes | None = None, headers: Mapping[str, str] | None = None,
                 expect: Iterable[int] = (200,), raw: bool = False, timeout: float | None = None) -> httpx.Response:
        """Send with re-authentication on 401 (once) and map unexpected statuses to RwsError."""
        query = dict(params or {})
        if self.version == 1 and not raw:
            query["json"] = "1"
        for attempt in (1, 2):
            resp = self._send(method, path, params=query, content=content, headers=headers, auth=self._auth,
                              timeout=timeout or self.timeouts.request_s)
            if resp.status_code != 401:
                break
            if attempt == 1:
                self._reauthenticate(method, path)
        else:
            raise RwsAuthError(f"{self.name}: {method} {path}: credentials rejected (HTTP 401) for user "
                               f"{self._credentials.user!r}")
        if resp.status_code not in tuple(expect):
            raise self._error(method, path, resp)
        self._last_ok = self._clock()
        return resp

    def _reauthenticate(self, method: str, path: str) -> None:
        """Forget cookies and the cached challenge; the next request authenticates a new session."""
        log.warning("%s: %s %s answered 401 (session expired?); re-authenticating", self.name, method, path)
        self.client.cookies.clear()
        self._auth = self._new_auth()

    def _send(self, method: str, path: str, *, params: Mapping[str, str], auth: httpx.Auth | None,
              timeout: float, content: bytes | None = None, headers: Mapping[str, str] | None = None) -> httpx.Response:
        """Send once per attempt, retrying 503 with bounded exponential backoff (same cookies)."""
        delay = self.policy.backoff_s
        for attempt in range(self.policy.retries + 1):
            resp = self._send_once(method, path, params=params, auth=auth, timeout=timeout, content=content,
                                   headers=headers)
            if resp.status_code != 503:
                return resp
            if attempt < self.policy.retries:
                wait = min(delay, self.policy.backoff_max_s)
                log.warning("%s: %s %s answered 503 (busy or session pool full); retry %d/%d in %.2f s",
                            self.name, method, path, attempt + 1, self.policy.retries, wait)
                self._sleep(wait)
                delay *= 2
        raise RwsBusy(f"{self.name}: {method} {path}: HTTP 503 after {self.policy.retries + 1} attempts "
                      "(controller busy or session pool exhausted; log out other RWS clients or wait about 5 min)")

    def _send_once(self, method: str, path: str, *, params: Mapping[str, str], auth: httpx.Auth | None,
                   timeout: float, content: bytes | None, headers: Mapping[str, str] | None) -> httpx.Response:
        """One HTTP exchange; httpx exceptions become ConnectionLost / DriverError here."""
        try:
            return self.client.request(method, path, params=params, content=content, headers=headers,
                                       auth=auth, timeout=self._httpx_timeout(timeout))
        except httpx.TimeoutException as exc:
            raise ConnectionLost(f"{self.name}: {method} {path}: no answer within {timeout:g} s "
                                 f"({type(exc).__name__})") from exc
        except httpx.TransportError as exc:
            raise ConnectionLost(f"{self.name}: {method} {path}: {type(exc).__name__}: {_short(str(exc))}") from exc
        except (httpx.HTTPError, httpx.InvalidURL) as exc:
            raise DriverError(f"{self.name}: {method} {path}: {type(exc).__name__}: {_short(str(exc))}") from exc

    def _json(self, resp: httpx.Response, path: str) -> Any:
        """Decoded JSON body or a DriverError."""
        try:
            return resp.json()
        except ValueError as exc:
            raise DriverError(f"{self.name}: GET {path}: answer is not JSON "
                              f"({resp.headers.get('content-type', '?')})") from exc

    def _error(self, method: str, path: str, resp: httpx.Response) -> RwsError:
        """RwsError naming the request, HTTP status and RWS return code."""
        try:
            code, msg = error_status(resp.json())
        except ValueError:
            code, msg = None, ""
        name = RETCODE_NAMES.get(code, "") if code is not None else ""
        detail = f" {code} {name}".rstrip() if code is not None else ""
        reason = f": {_short(msg, 120)}" if msg else ""
        return RwsError(f"{self.name}: {method} {path}: HTTP {resp.status_code}{detail}{reason}",
                        status=resp.status_code, code=code)
