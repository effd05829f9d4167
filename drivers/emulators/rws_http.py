"""RWS emulator basics: RobotWare return codes, constants, request/response records and HTTP helpers."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from email.message import Message
from typing import Iterable
from urllib.parse import parse_qs, urlsplit


REALM = "validusers@robapi.abb"
S_OK = 294912
E = {  # RobotWare return codes used here -> description
    -1073445879: "An argument specified by the client is not valid for this type of operation.",
    -1073445866: "The URL used to initialize the helper does not resolve to a valid object.",
    -1073445862: "Requested resource is held by someone else.",
    -1073445860: "The operation is not allowed in current operation mode.",
    -1073445859: "The user does not have required mastership for the operation.",
    -1073442816: "RAPID symbol was not found.",
    -1073442814: "The given file was not recognized as a program file.",
    -1073442813: "Ambiguous module name.",
    -1073442809: "Operation is illegal in current execution state.",
    -1073442802: "Operation not allowed due to semantic error(s).",
    -1073442801: "Given routine is not a legal entrypoint.",
    -1073442783: "No program pointer is available.",
    -1073438716: "Invalid path.",
    -1073438713: "The directory does not exist.",
    -1073438708: "File not found or could not be opened for reading.",
    -1073435887: "The requested action cannot be performed in the current state.",
    -1073414146: "Unspecified error.",
}
INVALIDARG, UNRESOLVED_URL, RESOURCE_HELD, MODE_REJECT, MASTER_REJECT = (
    -1073445879, -1073445866, -1073445862, -1073445860, -1073445859)
NO_SUCH_SYMBOL, INVALID_PROGRAMFILE, MOD_AMBNAME, EXEC_STATE, NO_PP = (
    -1073442816, -1073442814, -1073442813, -1073442809, -1073442783)
INVALID_PATH, DIR_NOT_EXIST, FILE_NOT_FOUND, INVALID_STATE, E_FAIL = (
    -1073438716, -1073438713, -1073438708, -1073435887, -1073414146)
RAPID_SEMANTIC_ERROR, ILLEGAL_ENTRYPOINT = -1073442802, -1073442801
ENTRY = "cal_run"      # CalServer's entry routine

TASK = "T_ROB1"
VOLUMES = ("HOME", "TEMP", "RAMDISK")
DEFAULT_LIMITS_DEG = ((-180, 180), (-95, 155), (-180, 75), (-400, 400), (-120, 120), (-400, 400))
UNUSED = 9e9


# The production program a cell runs: its main either calls CalServer's entry routine (the documented one-line
# integration) or not (the driver then sets the PP to cal_run and restores it to main when it is done).
CUSTOMER_PROGRAMS = {
    "calls": "MODULE MainModule\n    PROC main()\n        ! production program; campaigns run CalServer\n"
             "        cal_run;\n    ENDPROC\nENDMODULE\n",
    "plain": "MODULE MainModule\n    PERS num cycle_count:=0;\n    PROC main()\n        ! production cycle\n"
             "        cycle_count:=cycle_count+1;\n        WaitTime 1;\n    ENDPROC\nENDMODULE\n",
}

# --------------------------------------------------------------------------- HTTP plumbing


@dataclass
class Request:
    """One HTTP request as the emulator sees it (``target`` is the raw request-line target)."""
    method: str
    target: str
    headers: Message | dict
    body: bytes = b""

    @property
    def path(self) -> str:
        return urlsplit(self.target).path

    @property
    def query(self) -> dict[str, list[str]]:
        return parse_qs(urlsplit(self.target).query, keep_blank_values=True)

    def q(self, key: str, default: str | None = None) -> str | None:
        return self.query.get(key, [default])[0]

    def form(self) -> dict[str, str]:
        return {k: v[0] for k, v in parse_qs(self.body.decode("latin-1"), keep_blank_values=True).items()}

    def header(self, name: str) -> str:
        return str(self.headers.get(name) or "")


@dataclass
class Response:
    status: int
    body: bytes = b""
    headers: list[tuple[str, str]] = field(default_factory=list)


class EmulatedMotionFault(Exception):
    """Raised by a ``move_hook``: RAPID stops with an error in the event log (``code``, ``title``)."""

    def __init__(self, title: str, code: int = 50050) -> None:
        super().__init__(title)
        self.title, self.code = title, code


@dataclass
class Session:
    sid: str
    abbcx: str
    user: str
    last_seen: float


@dataclass
class Holder:
    """Who holds a mastership domain: a session id (remote client) or a foreign local/remote client."""
    session: str | None
    application: str
    location: str


@dataclass
class Fault:
    kind: str                  # error, motors_off, rapid_stop, hang
    message: str = ""
    code: int = 0
    after_s: float = 0.0


class Reject(Exception):
    """An RWS error answer (HTTP status, return code, detail)."""

    def __init__(self, status: int, code: int, detail: str = "") -> None:
        super().__init__(detail)
        self.status, self.code, self.detail = status, code, detail


def domain_key(domain: str) -> str:
    """1.0 ``rapid`` and 2.0 ``edit`` guard the same thing."""
    return "edit" if domain in ("rapid", "edit") else domain


def parse_cookies(header: str) -> dict[str, str]:
    out = {}
    for part in header.split(";"):
        name, sep, value = part.strip().partition("=")
        if sep:
            out[name] = value
    return out


def md5_hex(text: str) -> str:
    return hashlib.md5(text.encode("utf-8")).hexdigest()


def json_response(status: int, doc: dict, ctype: str) -> Response:
    return Response(status, json.dumps(doc).encode(), [("Content-Type", ctype)])


def xml_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def xhtml_list(items: Iterable[dict]) -> str:
    """RWS 1.0 XHTML: one ``li`` per item with ``span`` fields."""
    lis = []
    for item in items:
        spans = "".join(f'<span class="{xml_escape(k)}">{xml_escape(str(v))}</span>' for k, v in item.items()
                        if not k.startswith("_") and not isinstance(v, (dict, list)))
        lis.append(f'<li class="{xml_escape(item.get("_type", ""))}" title="{xml_escape(item.get("_title", ""))}">{spans}</li>')
    return ('<?xml version="1.0" encoding="utf-8"?><html xmlns="http://www.w3.org/1999/xhtml"><head>'
            '<title>rws</title></head><body><div class="state"><ul>' + "".join(lis) + "</ul></div></body></html>")
