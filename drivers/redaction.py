"""The one redaction function for text the software writes: URL user-info and known secrets are masked.

Every URL shown or stored (terminal, error lines, ``campaign.log``, ``log.jsonl``, JSON reports, crash reports, the
run's config copy) goes through :func:`redact`. Driver URLs never carry credentials (``campaign validate`` refuses
them); this is the net under that rule, for URLs that come from elsewhere (device replies, third-party callers).

* ``scheme://user:password@host`` -> ``scheme://***@host`` (any scheme, anywhere in the text; the user-info runs
  to the last ``@`` of the URL, so a password holding ``/``, ``#``, ``?`` or ``@`` is masked whole);
* a secret registered with :func:`register_secret` (a password read from the environment or a credentials file,
  or the user-info of a URL the config refused) -> ``***`` wherever it appears.

:func:`split_userinfo` is the one parser of a device URL's user-info: :func:`has_userinfo` (the config's refusal),
:func:`redact_url` and :func:`redact` all read it the same way.
"""
from __future__ import annotations

import re
import threading

MASK = "***"
MIN_SECRET_CHARS = 4            # shorter strings would mask ordinary text; such a password is not protected anyway

# scheme://USERINFO@ in free text: the user-info runs to the last '@' of the URL's token (whitespace, quotes and
# angle brackets end a URL in text); a password with whitespace is masked as a registered secret
_USERINFO_RE = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*://)[^\s\"'<>]*@")
_secrets: set[str] = set()
_lock = threading.Lock()
_secret_re: re.Pattern | None = None


def register_secret(value: str | None) -> None:
    """Mask ``value`` in everything :func:`redact` handles from now on (this process)."""
    global _secret_re
    if not value or len(value) < MIN_SECRET_CHARS:
        return
    with _lock:
        _secrets.add(value)
        _secret_re = re.compile("|".join(re.escape(s) for s in sorted(_secrets, key=len, reverse=True)))


def redact(text: str) -> str:
    """``text`` with URL user-info and registered secrets masked (unchanged when there is none)."""
    if "@" in text:
        text = _USERINFO_RE.sub(lambda m: m.group(1) + MASK + "@", text)
    pattern = _secret_re
    if pattern is not None:
        text = pattern.sub(MASK, text)
    return text


def split_userinfo(url: str) -> tuple[str, str | None, str]:
    """``(head, userinfo, rest)`` of a device URL: ``head`` the ``scheme://`` part ('' without one), ``userinfo``
    everything between it and the LAST ``@`` of the URL (None without an ``@``: the host follows the last ``@``,
    whatever characters the password holds), ``rest`` the host and what follows it."""
    scheme, sep, body = url.partition("://")
    head = scheme + sep if sep else ""
    body = body if sep else url
    userinfo, at, rest = body.rpartition("@")
    return (head, userinfo, rest) if at else (head, None, body)


def redact_url(url: str) -> str:
    """A URL-like config value safe to show: its user-info (:func:`split_userinfo`) masked, with or without a
    scheme (``user:pw@host`` -> ``***@host``)."""
    head, userinfo, rest = split_userinfo(url)
    return redact(head + (MASK + "@" if userinfo is not None else "") + rest)


def has_userinfo(url: str) -> bool:
    """True when ``url`` carries ``user[:password]@`` before its host (:func:`split_userinfo`)."""
    return split_userinfo(url)[1] is not None


def register_userinfo(url: str) -> None:
    """Register the user-info of ``url`` (and its password part) as secrets: a URL refused for carrying
    credentials is masked in every later line and file, whatever characters the password holds."""
    userinfo = split_userinfo(url)[1]
    if userinfo is not None:
        register_secret(userinfo)
        register_secret(userinfo.partition(":")[2])
