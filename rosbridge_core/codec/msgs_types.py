"""The :class:`~rosbridge_core.graph.Converter` of a ``msgs`` message class
(:class:`MsgsConverter`): what a Graph whose messages are ``msgs`` instances hands its
sessions, the in-memory Graph's (:mod:`rosbridge_core.memory`) and, reading CDR too, the
relay's (:mod:`bridge_server.zenoh.graph`).

A converter checks a value as the bridge's do (:class:`~rosbridge_core.interfaces.ConversionError`
naming the field path). Nothing here imports cbor2 (only :meth:`MsgsConverter.to_cbor_obj`
does, when a client asks for CBOR): a client-only install runs it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from msgs import cdr
from msgs.runtime import Message, ValidationError
from rosbridge_core.interfaces import ConversionError

__all__ = ["MsgsConverter"]


class MsgsConverter:
    """:class:`~rosbridge_core.graph.Converter` of one ``msgs`` message class."""

    def __init__(self, cls: type[Message]) -> None:
        self.cls = cls
        self._cbor: Callable[[bytes], dict[str, Any]] | None = None

    @property
    def type_name(self) -> str:
        """Canonical ``pkg/msg/Type``."""
        return self.cls._type

    @property
    def fields(self) -> tuple[str, ...]:
        """Field names in declaration order."""
        return tuple(self.cls._fields_and_types)

    def to_obj(self, msg: Any) -> dict[str, Any]:
        """The message as a JSON-ready dict (a NaN or infinity as null, as rosbridge)."""
        return msg.to_json()  # type: ignore[no-any-return]

    def to_json(self, msg: Any) -> str:
        """The message as compact JSON text."""
        return json.dumps(self.to_obj(msg), separators=(",", ":"), allow_nan=False,
                          ensure_ascii=False)

    def to_cbor_obj(self, msg: Any) -> Any:
        """The message as a CBOR-ready dict (byte strings, numeric arrays typed, RFC 8746)."""
        if self._cbor is None:
            import cbor2  # only a client asking for CBOR needs it

            self._cbor = cdr.decoder_for(self.cls, typed=cbor2.CBORTag)
        return self._cbor(cdr.encode(msg))

    def from_obj(self, obj: Any, path: str = "") -> Any:
        """A new message from a decoded object; ``ConversionError`` naming the field."""
        try:
            return self.cls.from_json(obj)
        except ValidationError as exc:
            where = ".".join(p for p in (path, exc.path) if p)
            raise ConversionError(where, exc.expected,
                                  detail=f"expected {exc.expected}, {exc.problem}") from None
