"""What clients send cannot forge or smuggle log lines.

Tokens never reach a log line (the patterns that find them), and no client-sent text can
start a line of its own or hide in one: control characters (newlines, NUL, escape sequences,
Unicode line separators) are written as escapes (``\\n``, ``\\x00``).
"""

from __future__ import annotations

import logging
import re
from urllib.parse import unquote_plus

__all__ = ["RedactTokens", "escape_controls", "install_log_redaction", "redact"]

_CONTROLS = re.compile(r"[\x00-\x08\x0a-\x1f\x7f\x85\u2028\u2029]")


def _escape(match: re.Match[str]) -> str:
    ch = match.group()
    if ch == "\n":
        return "\\n"
    if ch == "\r":
        return "\\r"
    return f"\\x{ord(ch):02x}" if ord(ch) < 0x100 else f"\\u{ord(ch):04x}"


def escape_controls(text: str) -> str:
    """``text`` with every control character written as a visible escape."""
    return _CONTROLS.sub(_escape, text) if _CONTROLS.search(text) else text


_SECRET_HEADERS = r"(?:proxy-)?authorization|x-rosbridge-session|(?:set-)?cookie"
"""Headers whose whole value is a secret, whatever its scheme: an ``Authorization`` of any
scheme (a token under ``Token``/``Basic`` is refused, yet it is a token), the session
token of :data:`~rosbridge_core.protocol.ops.SESSION_HEADER` (which resumes the session it
names), and cookies (``Cookie: token=...``, or another site's session cookie a browser sends
along)."""

_TOKEN_PATTERNS = (
    # a header line as websockets logs it at DEBUG (``< Authorization: Token abc``), and
    # headers as a repr shows them (``('Authorization', 'Token abc')``)
    re.compile(rf"(?im)(\b(?:{_SECRET_HEADERS})[ \t]*:[ \t]*)[^\r\n]+"),
    re.compile(rf"(?i)(['\"](?:{_SECRET_HEADERS})['\"]\s*[,:]\s*['\"])[^'\"]+"),
    re.compile(r"(?i)(bearer\s+)[^\s'\",]+"),
    re.compile(r"(?i)('mac':\s*'|\"mac\":\s*\")[^'\"]+"),
    # websockets' DEBUG line of a received data frame shows its start and end, not its keys:
    # an auth op's token can be there (as hex in a CBOR frame) where the key is elided.
    re.compile(r"(?m)^(< (?:TEXT|BINARY|CONT) ).+?(?= \[[^\]]*\]$)"),
    # a header line websockets could not parse, quoted whole in its exception: the second
    # line of a folded ``Authorization: Bearer\r\n <token>`` is the token alone
    re.compile(r"(?m)(invalid HTTP header (?:line|name|value): ).+"),
)

_REQUEST_TARGET = re.compile(r"\b([A-Z]{3,10} )(/\S*)")
"""A request line's method and target (websockets' DEBUG line of each request, and the
request line its exceptions quote)."""

_SEGMENT = re.compile(r"[^/?#]{20,}")
"""A path segment long enough to be a token (the helper's are 43 characters)."""

_QUERY_PARAM = re.compile(r"([?&;#])([^=&;?\s'\"#]*)=([^&# \r\n]*)")
"""One ``key=value`` of a query string (the key as sent, percent-encoded or not). The value
runs to the next ``&`` as the bridge reads it: a ``;``, a quote or a tab is part of it."""


def _redact_param(match: re.Match[str]) -> str:
    key = unquote_plus(match[2])
    if "token" in key.lower() and match[3]:
        return f"{match[1]}{match[2]}=<redacted>"
    return match[0]


def _secret_like(match: re.Match[str]) -> str:
    """A long path segment, or ``<redacted>`` if it could be a token: 20 characters or more
    mixing at least two of capitals, small letters and digits (the helper's tokens do)."""
    segment = match.group()
    classes = (any(c.isupper() for c in segment), any(c.islower() for c in segment),
               any(c.isdigit() for c in segment))
    return "<redacted>" if sum(classes) >= 2 else segment


def _redact_target(match: re.Match[str]) -> str:
    """A request target without a URL fragment (a client never sends one: ``#token=...``
    is a token in the wrong place) and without path segments that could be tokens."""
    target, hashed, _ = match[2].partition("#")
    path, question, query = target.partition("?")
    path = _SEGMENT.sub(_secret_like, path)
    return f"{match[1]}{path}{question}{query}{'#<redacted>' if hashed else ''}"


def redact(text: str) -> str:
    """``text`` with anything that looks like a token replaced by ``<redacted>``.

    A query parameter is matched on its key as the bridge reads it (percent-decoded, as
    :func:`~rosbridge_core.security.credentials.token_of` does), in any position and any
    case: ``?%74oken=``, ``&TOKEN=`` and ``&access_token=`` are all redacted. In a request
    line, the URL fragment (``GET /#token=...``) and path segments that could be tokens
    (``GET /<token>``) are redacted too; so are cookies, and a header line websockets could
    not parse (a folded ``Authorization: Bearer\r\n <token>``).
    """
    for rx in _TOKEN_PATTERNS:
        text = rx.sub(r"\1<redacted>", text)
    if "/" in text:
        text = _REQUEST_TARGET.sub(_redact_target, text)
    if "=" in text:
        text = _QUERY_PARAM.sub(_redact_param, text)
    return text


_TRACEBACKS = logging.Formatter()


class RedactTokens(logging.Filter):
    """A logging filter that scrubs tokens and escapes control characters in every record
    (install it on handlers). A traceback (``exc_info``) is scrubbed of tokens too, not
    escaped: an exception's text may quote what a client sent (websockets quotes a refused
    request line)."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Scrub ``record``'s message and traceback; never drop the record."""
        try:
            text = record.getMessage()
        except Exception:
            return True
        clean = escape_controls(redact(text))
        if clean != text:
            record.msg, record.args = clean, None
        if record.exc_info and not record.exc_text:
            record.exc_text = redact(_TRACEBACKS.formatException(record.exc_info))
        elif record.exc_text:
            record.exc_text = redact(record.exc_text)
        return True


def install_log_redaction() -> None:
    """Scrub tokens from every line the root logger's handlers write."""
    for handler in logging.getLogger().handlers:
        handler.addFilter(RedactTokens())
