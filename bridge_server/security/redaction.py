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


_SECRET_HEADERS = r"(?:proxy-)?authorization|x-rosbridge-session"
"""Headers whose whole value is a secret, whatever its scheme: an ``Authorization`` of any
scheme (a token under ``Token``/``Basic`` is refused, yet it is a token), and the session
token of :data:`~roslibpy_lite.protocol.ops.SESSION_HEADER` (which resumes the session it names)."""

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
)

_QUERY_PARAM = re.compile(r"([?&;])([^=&;?\s'\"#]*)=([^&# \r\n]*)")
"""One ``key=value`` of a query string (the key as sent, percent-encoded or not). The value
runs to the next ``&`` as the bridge reads it: a ``;``, a quote or a tab is part of it."""


def _redact_param(match: re.Match[str]) -> str:
    key = unquote_plus(match[2])
    if "token" in key.lower() and match[3]:
        return f"{match[1]}{match[2]}=<redacted>"
    return match[0]


def redact(text: str) -> str:
    """``text`` with anything that looks like a token replaced by ``<redacted>``.

    A query parameter is matched on its key as the bridge reads it (percent-decoded, as
    :func:`~bridge_server.security.credentials.token_of` does), in any position and any
    case: ``?%74oken=``, ``&TOKEN=`` and ``&access_token=`` are all redacted.
    """
    for rx in _TOKEN_PATTERNS:
        text = rx.sub(r"\1<redacted>", text)
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
