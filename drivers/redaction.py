"""The one redaction function for text the software writes: URL user-info and known secrets are masked.

Every URL shown or stored (terminal, error lines, ``campaign.log``, ``log.jsonl``, JSON reports, crash reports, the
run's config copy) goes through :func:`redact`. Driver URLs never carry credentials (``campaign validate`` refuses
them); this is the net under that rule, for URLs that come from elsewhere (device replies, third-party callers).

* ``scheme://user:password@host`` -> ``scheme://***@host`` (any scheme, anywhere in the text);
* a secret registered with :func:`register_secret` (a password read from the environment or a credentials file)
  -> ``***`` wherever it appears.
"""
from __future__ import annotations

import re
import threading
from urllib.parse import urlsplit

MASK = "***"
MIN_SECRET_CHARS = 4            # shorter strings would mask ordinary text; such a password is not protected anyway

# scheme://USERINFO@ : user-info runs to the last '@' before the host (no '/', '?', '#', whitespace or quotes)
_USERINFO_RE = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*://)[^\s/?#\"'<>]*@")
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


def redact_url(url: str) -> str:
    """A URL-like config value safe to show: whatever precedes an '@' in its authority is masked, with or without
    a scheme (``user:pw@host`` -> ``***@host``)."""
    scheme, sep, rest = url.partition("://") if "://" in url else ("", "", url)
    authority, slash, path = rest.partition("/")
    if "@" in authority:
        authority = MASK + "@" + authority.rpartition("@")[2]
    return redact(scheme + sep + authority + slash + path)


def has_userinfo(url: str) -> bool:
    """True when ``url`` carries ``user[:password]@`` before its host."""
    try:
        return "@" in urlsplit(url).netloc
    except ValueError:
        return "@" in url
