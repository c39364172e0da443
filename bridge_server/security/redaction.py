"""Tokens never reach a log line: the patterns that find them and the filter that scrubs them."""

from __future__ import annotations

import logging
import re

__all__ = ["RedactTokens", "install_log_redaction", "redact"]


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
    """A logging filter that scrubs tokens from every record (install it on handlers)."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Scrub ``record``'s message; never drop the record."""
        try:
            text = record.getMessage()
        except Exception:
            return True
        clean = redact(text)
        if clean != text:
            record.msg, record.args = clean, None
        return True


def install_log_redaction() -> None:
    """Scrub tokens from every line the root logger's handlers write."""
    for handler in logging.getLogger().handlers:
        handler.addFilter(RedactTokens())
