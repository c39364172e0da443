"""mkdocs hook: Sphinx cross-reference roles in docstrings render as code, not as raw text.

The packages' docstrings use Sphinx roles (``:class:`~roslibpy_lite.client.Client```),
which mkdocstrings passes through as text: the API pages would show
``:class:~roslibpy_lite.client.Client``. Each role becomes its target in code style, the
last dotted part only where the target starts with ``~`` (as Sphinx shows it).
"""

from __future__ import annotations

import re
from typing import Any

ROLE = re.compile(
    r":(?:py:)?(?:meth|class|func|mod|attr|exc|data|obj|const|meta|ref):<code>(~?)([^<]+)</code>"
)


def _code(match: re.Match[str]) -> str:
    tilde, target = match.group(1), match.group(2)
    return f"<code>{target.rsplit('.', 1)[-1] if tilde else target}</code>"


def on_page_content(html: str, **kwargs: Any) -> str:
    """Replace every rendered Sphinx role with its target as code."""
    return ROLE.sub(_code, html)
