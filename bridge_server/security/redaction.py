"""What clients send cannot forge or smuggle log lines.

Tokens never reach a log line (the patterns that find them), and no client-sent text can
start a line of its own or hide in one: control characters (newlines, NUL, escape sequences,
Unicode line separators) are written as escapes (``\\n``, ``\\x00``).
"""

from __future__ import annotations

import logging
import re

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


_TOKEN_PATTERNS = (
    re.compile(r"(?i)(bearer\s+)[^\s'\",]+"),
    re.compile(r"(?i)([?&]token=)[^&\s'\"]+"),
    re.compile(r"(?i)('mac':\s*'|\"mac\":\s*\")[^'\"]+"),
    # websockets' DEBUG line of a received data frame shows its start and end, not its keys:
    # an auth op's token can be there (as hex in a CBOR frame) where the key is elided.
    re.compile(r"(?m)^(< (?:TEXT|BINARY|CONT) ).+?(?= \[[^\]]*\]$)"),
)


def redact(text: str) -> str:
    """``text`` with anything that looks like a token replaced by ``<redacted>``."""
    for rx in _TOKEN_PATTERNS:
        text = rx.sub(r"\1<redacted>", text)
    return text


class RedactTokens(logging.Filter):
    """A logging filter that scrubs tokens and escapes control characters in every record
    (install it on handlers). A traceback (``exc_info``) is left as it is: it is the
    bridge's own text."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Scrub ``record``'s message; never drop the record."""
        try:
            text = record.getMessage()
        except Exception:
            return True
        clean = escape_controls(redact(text))
        if clean != text:
            record.msg, record.args = clean, None
        return True


def install_log_redaction() -> None:
    """Scrub tokens from every line the root logger's handlers write."""
    for handler in logging.getLogger().handlers:
        handler.addFilter(RedactTokens())
