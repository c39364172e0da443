"""The field model of :mod:`.convert`: each field of a message class classified once from its
rosidl slot type (container, element, bound, nested class), and the names the converter
and the validators share for it."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any, Final, Protocol

from rosidl_parser import definition as idl

from msgs._primitives import SIZED_INTEGER_RANGES

__all__ = ["INT_RANGES", "Field", "FromObj", "SubConverter"]

INT_RANGES: Final = SIZED_INTEGER_RANGES
# IDL names of the non-explicit integer types map onto explicit ones.
_INT_ALIASES: Final = {
    "short": "int16",
    "unsigned short": "uint16",
    "long": "int32",
    "unsigned long": "uint32",
    "long long": "int64",
    "unsigned long long": "uint64",
}
_FLOAT_NAMES: Final = {"float": "float32", "double": "float64", "long double": "float64"}


class FromObj(Protocol):
    """Signature of :attr:`~.convert.Converter.from_obj`."""

    def __call__(self, obj: Any, path: str = "") -> Any:
        """Build a new message from ``obj``; error paths are prefixed with ``path``."""


class SubConverter(Protocol):
    """What a field of a nested type uses of that type's :class:`~.convert.Converter`."""

    to_obj: Callable[[Any], dict[str, Any]]
    to_cbor_obj: Callable[[Any], dict[str, Any]]
    from_obj: FromObj
    _to_json_text: Callable[[Any], str]


class Field:
    """One message field, classified once from its rosidl slot type."""

    __slots__ = (
        "bound",
        "container",
        "elem",
        "elem_name",
        "name",
        "size",
        "sub",
        "subclass",
        "wide",
    )

    def __init__(self, name: str, slot_type: Any, owner: type[Any]) -> None:
        self.name = name
        self.container: str | None = None  # None, "array", "bseq", "useq"
        self.size = 0  # fixed size or maximum size
        t = slot_type
        if isinstance(t, idl.Array):
            self.container, self.size, t = "array", t.size, t.value_type
        elif isinstance(t, idl.BoundedSequence):
            self.container, self.size, t = "bseq", t.maximum_size, t.value_type
        elif isinstance(t, idl.UnboundedSequence):
            self.container, t = "useq", t.value_type
        self.bound: int | None = None
        self.wide = False
        self.subclass: type[Any] | None = None
        self.sub: SubConverter | None = None
        if isinstance(t, idl.BasicType):
            tn = t.typename
            if tn == "boolean":
                self.elem, self.elem_name = "bool", "bool"
            elif tn == "octet":
                self.elem, self.elem_name = "octet", "byte"
            elif tn in ("char", "wchar"):
                self.elem, self.elem_name = "char", tn
            elif tn in _FLOAT_NAMES:
                self.elem = self.elem_name = _FLOAT_NAMES[tn]
            else:
                self.elem = self.elem_name = _INT_ALIASES.get(tn, tn)
                if self.elem not in INT_RANGES:
                    raise TypeError(f"unsupported basic type {tn!r} for field {name!r}")
        elif isinstance(t, idl.AbstractString | idl.AbstractWString):
            self.elem = "string"
            self.wide = isinstance(t, idl.AbstractWString)
            self.bound = getattr(t, "maximum_size", None)
            self.elem_name = f"string<={self.bound}" if self.bound is not None else "string"
            if isinstance(t, idl.AbstractWString):
                self.elem_name = "w" + self.elem_name
        elif isinstance(t, idl.NamespacedType):
            self.subclass = _nested_class(t, owner)
            self.elem = "msg"
            self.elem_name = "/".join([*t.namespaces, t.name])
        else:
            raise TypeError(f"unsupported slot type {t!r} for field {name!r}")

    def expected(self) -> str:
        """Human name of the expected JSON value."""
        if self.container is None:
            return self.elem_name if self.elem != "msg" else f"object of type {self.elem_name}"
        item = self.elem_name if self.elem != "msg" else f"{self.elem_name} objects"
        if self.elem == "uint8":
            item = "uint8 (base64 string or array of ints)"
        elif self.elem == "octet":
            item = "byte (base64 string or array of ints)"
        if self.container == "array":
            return f"array of {self.size} {item}"
        if self.container == "bseq":
            return f"array of at most {self.size} {item}"
        return f"array of {item}"


def _nested_class(t: Any, owner: type[Any]) -> type[Any]:
    """The rclpy class of a nested field type.

    Action parts such as ``Fibonacci_Goal`` are not attributes of the
    ``pkg.action`` package, only of the private module that also defines the
    owning class, so look there second.
    """
    module = importlib.import_module(".".join(t.namespaces))
    found = getattr(module, t.name, None)
    if found is None:
        found = getattr(sys.modules[owner.__module__], t.name, None)
    if not isinstance(found, type):
        raise TypeError(f"cannot find the class of nested type {'/'.join([*t.namespaces, t.name])}")
    return found
