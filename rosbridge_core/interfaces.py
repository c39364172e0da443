"""The vocabulary every ROS side of the bridge shares: type names, the error roots, request args.

Nothing here imports ROS: the session layer, security and each
:class:`~rosbridge_core.graph.Graph` (the rclpy one in :mod:`bridge_server.rclpy_graph`, the
relay's on Zenoh in :mod:`bridge_server.zenoh.graph`) use the same names and raise the same
errors.

Type strings arrive from clients in two spellings, ``pkg/Type`` and
``pkg/<kind>/Type`` with kind one of ``msg``, ``srv``, ``action``. Both are
accepted everywhere; the canonical spelling the bridge answers with is
``pkg/<kind>/Type``.

Errors
------
::

    BridgeError                 root of the bridge's own errors
     +-- TypeNameError          malformed type string ("std_msgs", "a/b/c/d")
     +-- UnknownTypeError       well-formed name that names no installed type
     +-- ConversionError        a value that does not fit the ROS field it was meant for
     +-- ServiceCallError       a ROS service call that got no answer

Each error's message quotes the offending string (a conversion error names the
field path and a short description of what was received, never the whole payload).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any, Final, Literal, NamedTuple

__all__ = [
    "KINDS",
    "MISSING",
    "TYPE_RE",
    "BridgeError",
    "ConversionError",
    "Kind",
    "ReportedError",
    "ServiceCallError",
    "TypeName",
    "TypeNameError",
    "UnknownTypeError",
    "args_mapping",
    "canonical_name",
    "describe",
    "parse_type_name",
]

MISSING: Final = object()
"""A value that was not given (``ConversionError``'s ``got`` when a field is absent)."""

Kind = Literal["msg", "srv", "action"]
KINDS: Final = ("msg", "srv", "action")

_PKG_RE: Final = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
TYPE_RE: Final = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


class BridgeError(Exception):
    """Root of the errors raised by the bridge's own code."""


class ReportedError(BridgeError):
    """A failure its source has counted and logged already (a relay's robot that sent bytes
    that do not decode): whoever meets it drops the item without logging it again."""


class ServiceCallError(BridgeError):
    """A ROS service call got no answer (not in the graph, no server, timed out, a request
    that does not fit); the text says which, for the caller."""


class TypeNameError(BridgeError, ValueError):
    """A type string is malformed (wrong number of parts, bad characters, wrong kind)."""

    def __init__(self, name: object, reason: str) -> None:
        self.name = name
        self.reason = reason
        super().__init__(f"invalid type name {name!r}: {reason}")


class UnknownTypeError(BridgeError, LookupError):
    """A well-formed type string names no installed ROS interface."""

    def __init__(self, name: str, reason: str = "") -> None:
        self.name = name
        self.reason = reason
        text = f"unknown type {name!r}"
        if reason:
            text += f": {reason}"
        super().__init__(text)


class TypeName(NamedTuple):
    """A parsed type string: package, kind and type."""

    package: str
    kind: Kind
    type: str

    def __str__(self) -> str:
        return f"{self.package}/{self.kind}/{self.type}"


def parse_type_name(name: object, kind: Kind) -> TypeName:
    """Parse ``pkg/Type`` or ``pkg/<kind>/Type`` expecting interfaces of ``kind``.

    Raises :class:`TypeNameError` if ``name`` is not a string of that shape, or
    if it spells a different kind than ``kind`` (``std_srvs/srv/Empty`` given
    where a message is expected).
    """
    if not isinstance(name, str):
        raise TypeNameError(name, f"expected a string like 'pkg/{kind}/Type'")
    parts = name.split("/")
    if len(parts) == 2:
        pkg, typ = parts
    elif len(parts) == 3:
        pkg, got_kind, typ = parts
        if got_kind not in KINDS:
            raise TypeNameError(
                name, f"middle part must be one of msg, srv, action, got {got_kind!r}"
            )
        if got_kind != kind:
            raise TypeNameError(name, f"names a {got_kind} type where a {kind} type is expected")
    else:
        raise TypeNameError(name, f"expected 'pkg/Type' or 'pkg/{kind}/Type'")
    if not _PKG_RE.match(pkg):
        raise TypeNameError(name, f"bad package name {pkg!r}")
    if not TYPE_RE.match(typ):
        raise TypeNameError(name, f"bad type name {typ!r}")
    return TypeName(pkg, kind, typ)


def canonical_name(name: object, kind: Kind) -> str:
    """Return the canonical ``pkg/<kind>/Type`` spelling of a type string (no import)."""
    return str(parse_type_name(name, kind))


def args_mapping(
    args: Mapping[str, Any] | list[Any] | None, fields: Iterable[str], what: str
) -> Mapping[str, Any]:
    """A request's ``args`` as a mapping: positional values (a list, as roslibpy may
    send) are paired with ``fields`` in order; None is no fields set. ``what`` names the
    request in the error (``request``, ``goal``)."""
    if args is None:
        return {}
    if isinstance(args, list):
        names = tuple(fields)
        if len(args) > len(names):
            raise ConversionError(
                "args", what, detail=f"{len(args)} values given but the {what} has "
                f"{len(names)} fields" + (f" ({', '.join(names)})" if names else "")
            )
        return dict(zip(names, args, strict=False))
    return args


class ConversionError(BridgeError, ValueError):
    """A value could not be converted to (or from) the ROS field it was meant for.

    ``path`` is the full field path (``""`` for the message itself),
    ``expected`` names the expected type, and the message says what was got.
    """

    def __init__(self, path: str, expected: str, got: object = MISSING, detail: str = "") -> None:
        self.path = path
        self.expected = expected
        where = path or "message"
        if detail:
            text = f"{where}: {detail}"
        else:
            text = f"{where}: expected {expected}, got {describe(got)}"
        self.detail = detail
        super().__init__(text)


def describe(v: object) -> str:
    """A short description of a received value, never the whole payload."""
    if v is MISSING:
        return "nothing"
    if v is None:
        return "null"
    if v is True:
        return "true"
    if v is False:
        return "false"
    if isinstance(v, int):
        if abs(v) < 10**30:
            return f"integer {v}"
        return f"integer of {v.bit_length()} bits"
    if isinstance(v, float):
        return f"number {v!r}"
    if isinstance(v, str):
        shown = v if len(v) <= 40 else v[:37] + "..."
        return f"string {shown!r}" + (f" ({len(v)} characters)" if len(v) > 40 else "")
    if isinstance(v, list | tuple):
        return f"array of {len(v)} items"
    if isinstance(v, Mapping):
        return "object"
    if isinstance(v, bytes | bytearray | memoryview):
        return f"{len(v)} bytes"
    return type(v).__name__
