"""The in-memory graph's types (:class:`MsgsTypes`, the types part of
:class:`~rosbridge_core.memory.graph.MemoryGraph`): ``msgs`` classes by name, their converters
(:class:`~rosbridge_core.codec.msgs_types.MsgsConverter`), rosapi typedefs and definition texts.
"""

from __future__ import annotations

from typing import Any

from msgs import dynamic
from msgs.runtime import Message
from msgs.runtime import UnknownTypeError as WireUnknownType
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.interfaces import (
    BridgeError,
    UnknownTypeError,
    canonical_name,
    parse_type_name,
)

__all__ = ["MsgsTypes"]


class MsgsTypes:
    """The types part of the Graph port, from ``msgs`` (:attr:`wire_types`): classes by name,
    a converter per class (kept in ``_converters``, which the node makes), rosapi typedefs and
    definition texts."""

    wire_types: dynamic.TypeStore = dynamic.DEFAULT
    """The ``msgs`` classes of the graph's types."""

    _converters: dict[type[Message], MsgsConverter]

    def _load(self, name: str, kind: str) -> Any:
        canonical = canonical_name(name, kind)  # type: ignore[arg-type]
        types = self.wire_types
        try:
            return {"msg": types.lookup_message, "srv": types.lookup_service,
                    "action": types.lookup_action}[kind](canonical)
        except WireUnknownType:
            raise UnknownTypeError(name, f"no installed package provides {canonical}") from None

    def resolve_message(self, name: str) -> Any:
        """The ``msgs`` class of message type ``name`` (both spellings)."""
        return self._load(name, "msg")

    def resolve_service(self, name: str) -> Any:
        """The ``msgs`` service type named ``name``."""
        return self._load(name, "srv")

    def resolve_action(self, name: str) -> Any:
        """The ``msgs`` action type named ``name``."""
        return self._load(name, "action")

    def converter(self, cls: Any) -> MsgsConverter:
        """The converter of a ``msgs`` message class."""
        conv = self._converters.get(cls)
        if conv is None:
            conv = self._converters[cls] = MsgsConverter(cls)
        return conv

    def typedefs(self, name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
        """rosapi typedefs of a type (``part`` of a service or action) and its nested types."""
        from rosbridge_core.typedefs import msgs_typedefs

        cls = self._load(name, kind)
        canonical = canonical_name(name, kind)  # type: ignore[arg-type]
        if kind != "msg":
            cls, canonical = getattr(cls, part or ""), f"{canonical}_{part}"
        return msgs_typedefs(cls, canonical)

    def installed_interfaces(self) -> list[str]:
        """Every type ``msgs`` generates."""
        from msgs.runtime import available_types

        return available_types()

    def interface_definition(self, name: str) -> dict[str, Any]:
        """The full definition text of a type ``msgs`` has (the ``ros2msg`` layout)."""
        try:
            tn = next(t for t in (_parsed(name, k) for k in ("msg", "srv", "action"))
                      if t is not None and _has(self.wire_types, str(t)))
        except StopIteration:
            raise BridgeError(f"type: {name} is not installed on the robot (msgs has no "
                              "such type)") from None
        cls = self._load(str(tn), tn.kind)
        if tn.kind == "msg":
            return {"type": str(tn), "definition": dynamic.full_text(cls)}
        parts = ((cls.Request, cls.Response) if tn.kind == "srv"
                 else (cls.Goal, cls.Result, cls.Feedback))
        text = cls._definition.rstrip("\n") + "\n"
        seen = {p._type for p in parts}
        for part in parts:
            for dep in dynamic.full_text(part).split(dynamic.DELIMITER + "\n")[1:]:
                head = dep.split("\n", 1)[0]
                if head not in seen:
                    seen.add(head)
                    text += dynamic.DELIMITER + "\n" + dep
        return {"type": str(tn), "definition": text}


def _parsed(name: str, kind: str) -> Any:
    try:
        return parse_type_name(name, kind)  # type: ignore[arg-type]
    except BridgeError:
        return None


def _has(types: dynamic.TypeStore, name: str) -> bool:
    try:
        types.lookup(name)
    except WireUnknownType:
        return False
    return True
