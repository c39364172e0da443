"""Type names and messages: what the client checks locally, before anything is sent.

:func:`message_type` / :func:`service_type` turn a type string or a ``msgs``
class into the canonical name (refusing a malformed or unknown name with
"did you mean"); :func:`to_wire`, :func:`check_dict` and :func:`from_wire`
move messages between dicts or ``msgs`` instances and the rosbridge JSON form,
raising :class:`~roslibpy_lite.exceptions.InvalidMessageError` naming the field.
Used by the client (:mod:`roslibpy_lite.ros`), the handles
(:mod:`roslibpy_lite.handles`), actions and the in-memory bridge.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import difflib
import sys
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from msgs.runtime import (
    Action,
    Message,
    Service,
    UnknownTypeError,
    ValidationError,
    available_packages,
    available_types,
)
from msgs.runtime import lookup as _lookup

from .exceptions import InvalidMessageError, PartialMessageWarning, UsageError

__all__ = [
    "Completeness",
    "RawMessage",
    "bytes_fixer",
    "canonical_type",
    "check_dict",
    "check_name",
    "define_type",
    "from_wire",
    "held_warnings",
    "lookup_message_class",
    "message_type",
    "missing_fields",
    "service_type",
    "to_wire",
    "user_stacklevel",
    "warn_user",
]


_K = TypeVar("_K", Message, Service)

# --- type names ------------------------------------------------------------------------------

def check_name(name: object, what: str) -> None:
    """Raise UsageError unless ``name`` (of a topic, service, action...) is a non-empty string."""
    if not isinstance(name, str) or not name:
        article = "an" if what[:1] in "aeiou" else "a"
        raise UsageError(f"{article} {what} name must be a non-empty string, got {name!r}")


def canonical_type(name: str, kind: str) -> str:
    """``pkg/Name`` → ``pkg/<kind>/Name``; names already in that form are returned as they are."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/{kind}/{parts[1]}"
    return name


def _check_type_string(type_: str, kind: str) -> None:
    parts = type_.split("/")
    if not (2 <= len(parts) <= 3 and all(parts)) or (len(parts) == 3 and parts[1] != kind):
        raise UsageError(
            f"type {type_!r} is not a {kind} type name: expected 'package/Name' or "
            f"'package/{kind}/Name'"
        )


def _check_known(name: str, kind: str) -> None:
    """Refuse a type ``msgs`` should know but does not (its package is there, the name is not).

    Types of packages ``msgs`` does not generate are left to the bridge.
    """
    package = name.split("/", 1)[0]
    if package not in _packages():
        return
    try:
        found = _lookup(name)
    except UnknownTypeError:
        found = None
    wanted = Message if kind == "msg" else Service
    if isinstance(found, type) and issubclass(found, wanted):
        return
    known = [t for t in available_types(package) if t.split("/")[1] == kind]
    by_name = {t.rsplit("/", 1)[1]: t for t in known}
    close = [by_name[n] for n in difflib.get_close_matches(name.rsplit("/", 1)[1], by_name,
                                                              n=3, cutoff=0.6)]
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else (
        f"; {package} has: {', '.join(t.rsplit('/', 1)[1] for t in known[:12])}"
        + (", ..." if len(known) > 12 else "") if known else ""
    )
    raise UsageError(f"unknown {kind} type {name!r}: {package} has no such {kind}{hint}")


_PACKAGES: list[frozenset[str]] = []


def name_hint(name: str, names: Iterable[str], kind: str = "topics") -> str:
    """``"did you mean '/imu'?"`` for a misspelt ``name`` among ``names`` (the same name in
    other letter case first), else the list of ``names`` (at most 12); ``""`` for none."""
    known = sorted({str(n) for n in names} - {name})
    same = [n for n in known if n.lower() == name.lower()]
    close = same or difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    if close:
        return f"did you mean {' or '.join(repr(c) for c in close)}?"
    if not known:
        return f"there are no {kind}"
    return f"the {kind} are: {', '.join(known[:12])}{', ...' if len(known) > 12 else ''}"


def _packages() -> frozenset[str]:
    if not _PACKAGES:
        _PACKAGES.append(frozenset(available_packages()))
    return _PACKAGES[0]


def _wrong_class(type_: object, kind: str) -> UsageError:
    what = "a message" if kind == "msg" else "a service"
    if isinstance(type_, type) and issubclass(type_, Message | Service | Action):
        actual = (
            "a message" if issubclass(type_, Message)
            else "a service" if issubclass(type_, Service) else "an action"
        )
        return UsageError(
            f"{type_._type} is {actual} type, but {what} type is needed here"
            + ("; for a service pass the service class (e.g. AddTwoInts), not its Request"
               if kind == "srv" and actual == "a message" else "")
        )
    return UsageError(f"{what} type must be a type string or a msgs class, got {type_!r}")


def message_type(type_: str | type[Message]) -> tuple[str, type[Message] | None]:
    """The canonical type name and (for a generated class) the class of a message type.

    Raises:
        UsageError: a malformed name, a name ``msgs`` should know but does not
            (with "did you mean"), or a class of another kind.
    """
    return _name_and_class(type_, "msg", Message)


def service_type(type_: str | type[Service]) -> tuple[str, type[Service] | None]:
    """The canonical type name and (for a generated class) the class of a service type.

    Raises:
        UsageError: as for :func:`message_type`.
    """
    return _name_and_class(type_, "srv", Service)


def _name_and_class(
    type_: str | type[_K], kind: str, base: type[_K]
) -> tuple[str, type[_K] | None]:
    if isinstance(type_, str):
        _check_type_string(type_, kind)
        name = canonical_type(type_, kind)
        _check_known(name, kind)
        return name, None
    if isinstance(type_, type) and issubclass(type_, base):
        return type_._type, type_
    raise _wrong_class(type_, kind)


def lookup_message_class(type_name: str) -> type[Message] | None:
    """The generated class of a message type name, or None when there is none."""
    try:
        found = _lookup(type_name)
    except UnknownTypeError:
        return None
    return found if isinstance(found, type) and issubclass(found, Message) else None


def to_wire(
    msg: Any, type_name: str, cls: type[Message] | None, what: str
) -> Mapping[str, Any]:
    """The rosbridge JSON form of ``msg`` (a dict or a message instance) of type ``type_name``.

    A message instance must be of the type (``cls`` when given, else the same
    type name) and is validated.

    Raises:
        UsageError: a message of another type, or neither a dict nor a message.
        InvalidMessageError: a message instance with a field that does not fit.
    """
    if isinstance(msg, Message):
        if cls is not None:
            if not isinstance(msg, cls):
                raise UsageError(f"{what}: expected a {cls._type} message, got {msg._type}")
        elif msg._type != type_name:
            raise UsageError(f"{what}: expected a {type_name} message, got {msg._type}")
        try:
            msg.validate()
        except ValidationError as exc:
            raise InvalidMessageError(f"{what}: {exc}", path=exc.path) from None
        return msg.to_json()
    if isinstance(msg, Mapping):
        return msg
    raise UsageError(
        f"{what}: a message must be a dict or a {type_name} instance, got {type(msg).__name__}"
    )


_BULK = 1024


def _changed(value: Mapping[str, Any], changes: Iterable[tuple[str, Any, Any]]
             ) -> Mapping[str, Any]:
    """``value`` with each ``(key, old, new)`` where ``new is not old`` applied to a copy;
    ``value`` itself when nothing changed."""
    out: dict[str, Any] | None = None
    for key, old, new in changes:
        if new is not old:
            if out is None:
                out = dict(value)
            out[key] = new
    return value if out is None else out


def _outline(value: Any) -> Any:
    """``value`` with bulky strings, byte strings and lists emptied (their kind kept).

    Returns ``value`` itself when nothing in it is bulky (no copy).
    """
    if isinstance(value, Mapping):
        return _changed(value, ((k, v, _outline(v)) for k, v in value.items()
                                if not isinstance(v, int | float)))
    if isinstance(value, str | bytes | list) and len(value) > _BULK:
        return value[:0]
    if isinstance(value, list) and value and isinstance(value[0], Mapping):
        items = [_outline(v) for v in value]
        return value if all(a is b for a, b in zip(items, value, strict=True)) else items
    return value


def check_dict(wire: Mapping[str, Any], cls: type[Message] | None, what: str) -> None:
    """Check a dict against ``cls`` (if given), as :class:`InvalidMessageError` naming the field.

    Field names and the kind of every value are checked; the contents of bulky values
    (more than 1024 items or characters: image data, point clouds) are left to the
    bridge, so publishing an image as a dict costs no second decode here.
    """
    if cls is not None and not isinstance(wire, Message):
        from_wire(_outline(wire), cls, what)


def from_wire(raw: Mapping[str, Any], cls: type[Message], what: str) -> Message:
    """Build a ``cls`` instance from its wire form, as :class:`InvalidMessageError` on failure."""
    try:
        return cls.from_json(raw)
    except ValidationError as exc:
        raise InvalidMessageError(f"{what}: {exc}", path=exc.path) from None


# --- the shape of a type: its byte fields, its fields a dict left out -------------------------

def _element(idl: str) -> tuple[str, bool]:
    """A field's element type and whether the field is an array (``msgs``' spelling)."""
    if idl.startswith("sequence<"):
        return idl[len("sequence<"):-1].split(",", 1)[0].strip(), True
    if idl.endswith("]") and "[" in idl:
        return idl[:idl.index("[")], True
    return idl, False


_Fix = Callable[[Any], Any]
_FIXERS: dict[str, _Fix | None] = {}

_b64decode: Callable[..., bytes]
try:  # SIMD base64 where installed (the data extra): a 640x480 RGB frame in ~0.1 ms, not ~4
    from pybase64 import b64decode as _b64decode
except ImportError:  # pragma: no cover - the client alone needs nothing more
    _b64decode = base64.b64decode


def _b64(value: Any) -> Any:
    if isinstance(value, str):
        try:
            return _b64decode(value, validate=True)
        except (binascii.Error, ValueError):
            return value  # not base64: left for the type check to name
    if isinstance(value, list):
        try:
            return bytes(value)
        except (TypeError, ValueError):
            return value
    return value


def _each(fix: _Fix) -> _Fix:
    def each(values: Any) -> Any:
        if not isinstance(values, list):
            return values
        fixed = [fix(v) for v in values]
        return values if all(a is b for a, b in zip(fixed, values, strict=True)) else fixed
    return each


def _fields_fixer(steps: list[tuple[str, _Fix]]) -> _Fix:
    def fix(wire: Any) -> Any:
        if not isinstance(wire, Mapping):
            return wire
        return _changed(wire, ((name, value, conv(value)) for name, conv in steps
                               if (value := wire.get(name)) is not None))
    return fix


def bytes_fixer(type_name: str) -> Callable[[Any], Any] | None:
    """A function giving a wire dict of ``type_name`` with its ``uint8[]``/``char[]`` fields
    (nested ones too) as ``bytes``, however they came (base64 text under JSON, a list of
    ints); None when the type has no such field or ``msgs`` does not know it.

    The function returns its argument itself when nothing needed changing (CBOR's bytes),
    else a shallow copy with the changed fields. Built once per type.
    """
    if type_name in _FIXERS:
        return _FIXERS[type_name]
    _FIXERS[type_name] = None  # a type that contains itself (through an array) ends here
    cls = lookup_message_class(type_name)
    steps: list[tuple[str, _Fix]] = []
    for name, idl in (cls._fields_and_types.items() if cls is not None else ()):
        elem, is_array = _element(idl)
        if is_array and elem in ("uint8", "char"):
            steps.append((name, _b64))
        elif "/" in elem:
            inner = bytes_fixer(elem)
            if inner is not None:
                steps.append((name, _each(inner) if is_array else inner))
    fixer = _fields_fixer(steps) if steps else None
    _FIXERS[type_name] = fixer
    return fixer


def missing_fields(wire: Mapping[str, Any], cls: type[Message]) -> list[str]:
    """The fields of ``cls`` that the dict ``wire`` leaves out, as dotted paths
    (``angular``, ``header.stamp``; ``points[].z`` inside arrays of messages), in
    definition order. Only the dicts given are walked: a nested message left out is one
    name, and one given as ``{}`` asks for its defaults (nothing is missing there).
    """
    out: list[str] = []
    _missing_into(out, "", wire, cls)
    return out


def _missing_into(out: list[str], prefix: str, wire: Mapping[str, Any], cls: type[Message]
                  ) -> None:
    for name, idl in cls._fields_and_types.items():
        if name not in wire:
            out.append(prefix + name)
            continue
        elem, is_array = _element(idl)
        if "/" not in elem:
            continue
        inner = lookup_message_class(elem)
        value = wire[name]
        if inner is None:
            continue
        if not is_array:
            if isinstance(value, Mapping) and value:  # {}: that message's defaults, asked for
                _missing_into(out, f"{prefix}{name}.", value, inner)
            continue
        seen: set[str] = set()
        for item in value if isinstance(value, list) else ():
            if isinstance(item, Mapping):
                found: list[str] = []
                _missing_into(found, f"{prefix}{name}[].", item, inner)
                out.extend(f for f in found if f not in seen)
                seen.update(found)


_PACKAGE_DIR = str(Path(__file__).resolve().parent)


def user_stacklevel() -> int:
    """The ``stacklevel`` of the first frame outside roslibpy_lite (the user's call)."""
    frame = sys._getframe(1)
    level = 1
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE_DIR):
        frame = frame.f_back  # type: ignore[assignment]
        level += 1
    return level


_HELD = threading.local()


def warn_user(warning: Warning) -> None:
    """Give ``warning`` at the user's call, or keep it for :func:`held_warnings` to hand
    over (the blocking client re-gives it on the caller's thread, not its loop thread)."""
    held: list[Warning] | None = getattr(_HELD, "warnings", None)
    if held is not None:
        held.append(warning)
        return
    warnings.warn(warning, stacklevel=user_stacklevel())


@contextlib.contextmanager
def held_warnings() -> Iterator[list[Warning]]:
    """Keep the warnings :func:`warn_user` gives in this thread during the block (no await
    inside it), in the list it yields."""
    before = getattr(_HELD, "warnings", None)
    held: list[Warning] = []
    _HELD.warnings = held
    try:
        yield held
    finally:
        _HELD.warnings = before


class Completeness:
    """The rule for dicts that leave fields out: the bridge fills in their defaults (as
    rosbridge does: users publish partial Twists), and the client says so once per type
    and set of missing fields with a :class:`~roslibpy_lite.exceptions.PartialMessageWarning`
    naming them; ``strict`` refuses such dicts instead. An empty dict asks for every
    default as plainly as ``None`` does: no warning (``strict`` refuses it too).

    Args:
        strict: the client's default (``strict=`` on ``connect`` and ``MockRos``).
    """

    def __init__(self, strict: bool = False) -> None:
        self.strict = strict
        self._seen: set[tuple[str, tuple[str, ...]]] = set()

    def check(self, wire: Mapping[str, Any], cls: type[Message] | None, what: str,
              strict: bool | None = None) -> None:
        """Warn once (or, strict, raise) if the dict ``wire`` of ``cls`` leaves fields out.

        Raises:
            InvalidMessageError: strict, and fields are missing (all named).
        """
        if cls is None or isinstance(wire, Message):
            return
        missing = missing_fields(wire, cls)
        if not missing:
            return
        names = ", ".join(missing)
        if self.strict if strict is None else strict:
            raise InvalidMessageError(
                f"{what}: the {cls._type} dict lacks {names} (strict=True wants every field)",
                path=missing[0])
        if not wire:
            return  # {}: every default, asked for as plainly as None
        key = (cls._type, tuple(missing))
        if key in self._seen:
            return
        self._seen.add(key)
        warn_user(PartialMessageWarning(
            f"{what}: the {cls._type} dict lacks {names}; the bridge fills in their defaults "
            "(said once per type and field set; strict=True refuses such dicts)"))


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One message as the robot serialized it (from a ``raw=True`` subscription).

    ``data`` is the CDR bytes with their 4-byte encapsulation header, exactly what
    ``rclpy.serialization.serialize_message`` gives; ``stamp_ns`` is when the bridge
    took the message from ROS (nanoseconds since the epoch), or when this client got
    it if the bridge sent no stamp. Nothing is decoded until :meth:`decode` is called.
    """

    topic: str
    type_name: str
    data: bytes
    stamp_ns: int

    def decode(self) -> Message:
        """The typed message (its type must be generated, or loaded with ``load_types``).

        Raises:
            UsageError: msgs does not know the type.
            msgs.cdr.CdrError: the bytes do not decode as the type says.
        """
        from msgs.cdr import decode

        cls = lookup_message_class(self.type_name)
        if cls is None:
            raise UsageError(f"{self.type_name} is not a type msgs knows: load its "
                             "definition first (await ros.load_types(...))")
        return cls.from_json(decode(self.data, cls))

    def __repr__(self) -> str:
        return (f"RawMessage(topic={self.topic!r}, type_name={self.type_name!r}, "
                f"data=<{len(self.data)} bytes>, stamp_ns={self.stamp_ns})")


def define_type(type_name: str, definition: str) -> type[Message] | type[Service] | type[Action]:
    """A typed class for an interface msgs does not generate, from its definition text.

    ``definition`` is the ``.msg``/``.srv``/``.action`` text, followed by the
    definitions of the message types it uses that msgs does not know, each after a
    line of 80 ``=`` and ``MSG: pkg/msg/Name`` (the layout of an MCAP schema and of
    the bridge's ``/rosapi/interface_definition``). Afterwards the type is known by
    name everywhere, MockRos included, which then checks messages of it as the
    bridge will. ``ros.load_types(...)`` does the same with the robot's own text.

    Raises:
        msgs.parser.DefinitionError: the text does not parse (names the line).
    """
    from msgs.dynamic import load

    return load(type_name, definition)
