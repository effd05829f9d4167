"""RWS emulator: authentication, sessions and representations (a mixin of ``RwsEmulator``)."""

from __future__ import annotations

import base64
import hmac
import secrets
import time
from typing import Any
from urllib.request import parse_http_list, parse_keqv_list

from .rws_http import (E, REALM, Request, Response, S_OK, Session, json_response, md5_hex, parse_cookies, xhtml_list,
                       xml_escape)


class AuthMixin:
    """Digest/Basic authentication, session cookies, media types and the JSON/XHTML representations."""

    # -- authentication and sessions

    def _authenticate(self, req: Request) -> tuple[Session | None, list[str], Response | None]:
        """(session, Set-Cookie values, refusal). Cookie first, then Digest (1.0) / Basic (2.0)."""
        self._expire_idle()
        sid = parse_cookies(req.header("Cookie")).get("-http-session-")
        if self._fail_401 > 0:
            self._fail_401 -= 1
            if sid in self._sessions:
                self._drop_session(sid)
            self._nonces.clear()
            return None, [], self._challenge(stale=True)
        if sid in self._sessions:
            session = self._sessions[sid]
            session.last_seen = time.monotonic()
            return session, [], None
        user, stale = self._check_credentials(req)
        if user is None:
            self.counts["auth_failures"] += bool(req.header("Authorization"))
            return None, [], self._challenge(stale=stale)
        if len(self._sessions) >= self.max_sessions:
            return None, [], Response(503, b"Too many sessions", [("Content-Type", "text/plain")])
        return self._new_session(user)

    def _new_session(self, user: str) -> tuple[Session, list[str], None]:
        session = Session(secrets.token_hex(12), secrets.token_hex(8), user, time.monotonic())
        self._sessions[session.sid] = session
        self.counts["sessions"] += 1
        return session, [f"-http-session-={session.sid}; path=/; httponly", f"ABBCX={session.abbcx}; path=/"], None

    def _drop_session(self, sid: str) -> None:
        self._sessions.pop(sid, None)
        for domain, holder in list(self.mastership.items()):
            if holder.session == sid:
                del self.mastership[domain]

    def _expire_idle(self) -> None:
        now = time.monotonic()
        for sid, s in list(self._sessions.items()):
            if now - s.last_seen > self.session_idle_s:
                self._drop_session(sid)

    def _check_credentials(self, req: Request) -> tuple[str | None, bool]:
        """(user or None, stale nonce?) from the Authorization header."""
        auth = req.header("Authorization")
        scheme, _, rest = auth.partition(" ")
        if self.version == 1 and scheme.lower() == "digest":
            return self._check_digest(req, rest)
        if self.version == 2 and scheme.lower() == "basic":
            return self._check_basic(rest), False
        return None, False

    def _check_digest(self, req: Request, fields_text: str) -> tuple[str | None, bool]:
        """RFC 7616 Digest with MD5 and qop=auth against this request's method and target."""
        f = parse_keqv_list(parse_http_list(fields_text))
        needed = ("username", "realm", "nonce", "uri", "response", "qop", "nc", "cnonce")
        if any(k not in f for k in needed) or f["realm"] != REALM or f["qop"] != "auth":
            return None, False
        if f.get("algorithm", "MD5").upper() != "MD5" or f["uri"] != req.target:
            return None, False
        if f["nonce"] not in self._nonces:
            return None, True
        ha1 = md5_hex(f"{f['username']}:{REALM}:{self._password}")
        ha2 = md5_hex(f"{req.method}:{f['uri']}")
        expected = md5_hex(f"{ha1}:{f['nonce']}:{f['nc']}:{f['cnonce']}:auth:{ha2}")
        ok = hmac.compare_digest(expected, f["response"]) and f["username"] == self._user
        return (f["username"] if ok else None), False

    def _check_basic(self, token: str) -> str | None:
        try:
            user, _, password = base64.b64decode(token.strip()).decode("utf-8").partition(":")
        except (ValueError, UnicodeDecodeError):
            return None
        ok = hmac.compare_digest(user.encode(), self._user.encode()) and \
            hmac.compare_digest(password.encode(), self._password.encode())
        return user if ok else None

    def _challenge(self, *, stale: bool = False) -> Response:
        """401 with a fresh Digest nonce (1.0) or a Basic challenge (2.0)."""
        if self.version == 1:
            nonce = secrets.token_hex(16)
            self._nonces[nonce] = time.monotonic()
            value = (f'Digest realm="{REALM}", domain="/", qop="auth", nonce="{nonce}", opaque="{self._opaque}", '
                     f'algorithm="MD5", stale="{"TRUE" if stale else "FALSE"}"')
        else:
            value = f'Basic realm="{REALM}"'
        return Response(401, b"", [("WWW-Authenticate", value)])

    def _check_media(self, req: Request) -> Response | None:
        """RWS 2.0 media-type versioning: Accept and body types must carry ``;v=2.0``."""
        if self.version != 2 or req.path.startswith("/logout"):
            return None
        files = req.path.startswith("/fileservice")
        if req.method in ("GET", "HEAD") and not files and "v=2.0" not in req.header("Accept"):
            return Response(406, b"", [("Content-Type", "text/plain")])
        if req.method in ("POST", "PUT") and req.body and "v=2.0" not in req.header("Content-Type"):
            return Response(415, b"", [("Content-Type", "text/plain")])
        return None

    # -- representations

    def _ok(self, req: Request, items: list[dict], *, collection: bool = False) -> Response:
        """200 with items in the flavour's envelope (1.0 JSON/XHTML, 2.0 HAL)."""
        base = {"href": f"{self.base_url}{req.path.rsplit('/', 1)[0]}/"}
        if self.version == 1 and req.q("json") != "1":
            return Response(200, xhtml_list(items).encode(), [("Content-Type", "application/xhtml+xml")])
        if self.version == 1:
            doc: dict[str, Any] = {"_links": {"base": base}, "_embedded": {"_state": items}}
            return json_response(200, doc, "application/json")
        if collection:
            doc = {"_links": {"base": base, "self": {"href": ""}}, "_embedded": {"resources": items}}
        else:
            doc = {"_links": {"base": base, "self": {"href": ""}}, "status": {"code": S_OK}, "state": items}
        return json_response(200, doc, "application/hal+json;v=2.0")

    def _error(self, req: Request, status: int, code: int, detail: str = "") -> Response:
        """Error envelope: 1.0 ``_embedded.status`` (or XHTML), 2.0 ``status``."""
        msg = f"rws_emulator.py[0] {E.get(code, 'Error.')} {detail} code:{code} icode:-1".replace("  ", " ")
        base = {"href": f"{self.base_url}/"}
        if self.version == 1 and req.q("json") != "1":
            body = (f'<html><body><div class="status"><span class="code">{code}</span>'
                    f'<span class="msg">{xml_escape(msg)}</span></div></body></html>')
            return Response(status, body.encode(), [("Content-Type", "application/xhtml+xml")])
        if self.version == 1:
            return json_response(status, {"_links": {"base": base}, "_embedded": {"status": {"code": code, "msg": msg},
                                                                           "_state": []}}, "application/json")
        return json_response(status, {"_links": {"base": base}, "status": {"code": code, "msg": msg}},
                     "application/hal+json;v=2.0")
