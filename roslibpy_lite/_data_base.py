"""What :mod:`roslibpy_lite.data` and its column reader (:mod:`roslibpy_lite._data_columns`)
share: the ``data`` extra's imports (numpy, pandas), said missing with the line that
installs them, and the flat field names a ``fields=`` argument picks."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from .exceptions import UsageError


def _numpy() -> Any:
    try:
        import numpy
    except ImportError:
        raise UsageError("roslibpy_lite.data needs numpy: pip install 'roslibpy-lite[data]'"
                         ) from None
    return numpy


def _pandas() -> Any:
    try:
        import pandas
    except ImportError:
        raise UsageError("roslibpy_lite.data needs pandas: pip install 'roslibpy-lite[data]'"
                         ) from None
    return pandas


def _chosen(names: Mapping[str, Any] | Sequence[str], fields: Iterable[str]) -> list[str]:
    """The flat ``names`` that ``fields`` pick, in order: a name, or every name under it."""
    out: dict[str, None] = {}
    for name in fields:
        if name in names:
            out[name] = None
            continue
        inner = [k for k in names if k.startswith(name + ".")]
        if not inner:
            raise UsageError(f"no field {name!r} (the message has {', '.join(names)})")
        out.update(dict.fromkeys(inner))
    return list(out)
