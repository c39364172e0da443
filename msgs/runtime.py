"""The base of the generated message classes, and type lookup by name.

Contract (what the client relies on):

* :class:`Message` is the base of every generated message class. The classes are
  mutable, slotted, keyword-only dataclasses (``String(data="hi")``; like rclpy, fields
  may be reassigned). Building one checks each field's kind, range and length (an
  unknown field is a ``TypeError``, a value that does not fit a :class:`ValidationError`
  naming the field, the expected type and the message type); a nested message was
  checked when it was built. Fields reassigned later are checked by ``validate()``.
  Class attributes:

  - ``_type``: ``"pkg/msg/Name"``; service parts ``"pkg/srv/Name_Request"`` /
    ``"pkg/srv/Name_Response"``; action parts ``"pkg/action/Name_Goal"``,
    ``"_Result"``, ``"_Feedback"``.
  - ``_definition``: the definition text of the type (of this part, for services and
    actions).
  - ``_fields_and_types``: field name -> type string, in rclpy's
    ``get_fields_and_field_types()`` spelling: ``boolean``, ``octet``, ``uint8``, ``float``
    (float32), ``double`` (float64), ``int32``, ``string``, ``string<10>`` (bounded),
    ``wstring``, ``std_msgs/Header`` (nested), ``int32[3]`` (fixed array),
    ``sequence<int32, 5>`` (bounded), ``sequence<int32>`` (unbounded).

  Python-side field values: ``uint8``/``char`` arrays (fixed or not) are ``bytes``;
  every other array is a ``list``; strings ``str``; integers (``byte`` too) ``int``;
  floats ``float``; nested messages instances of their class.

* ``msg.to_json()`` gives the rosbridge JSON form: ``uint8[]``/``char[]`` as a base64
  string, NaN and +-Inf floats as ``None``, nested messages as dicts (Time and Duration
  are plain ``{"sec", "nanosec"}`` messages). It does not validate; call
  ``msg.validate()`` first when the values may be wrong.
* ``Cls.from_json(data)`` accepts the wire form from JSON or CBOR: ``uint8[]`` as base64
  string, bytes-like or list of ints; numeric arrays as list, tuple, ``array.array`` or
  memoryview; ``None`` for a float means NaN. Missing fields keep their defaults. An
  unknown field, a value of the wrong kind or out of range raises
  :class:`ValidationError`, whose message names the field path (``pose.position.x``)
  and the expected type.
* :class:`Service` (``Request``, ``Response``) and :class:`Action` (``Goal``,
  ``Result``, ``Feedback``) are namespaces, not instantiable.
* :func:`lookup` finds a type by name in either spelling (``std_msgs/String`` or
  ``std_msgs/msg/String``), importing its generated module on first use.

This module is the registry (lookup by name, :func:`register`, the listing of generated
types) and the one import path of all the above. The base classes live in
:mod:`msgs._message`, each field's checker, converter and encoder in :mod:`msgs._fields`,
the errors in :mod:`msgs._errors`.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from pathlib import Path

from ._errors import UnknownTypeError, ValidationError
from ._message import Action, Message, Service

__all__ = [
    "Action",
    "Find",
    "Message",
    "Service",
    "UnknownTypeError",
    "ValidationError",
    "available_packages",
    "available_types",
    "lookup",
    "lookup_action",
    "lookup_generated",
    "lookup_message",
    "lookup_service",
    "register",
]


_KINDS = ("msg", "srv", "action")
_NAME_RE = re.compile(
    r"^(?P<pkg>[a-z][a-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?(?P<name>[A-Z][A-Za-z0-9_]*)$"
)
_RESERVED = frozenset({"runtime", "parser", "generator", "interfaces"})
_CACHE: dict[str, type[Message] | type[Service] | type[Action]] = {}


def _find(
    package: str, kind: str, name: str
) -> type[Message] | type[Service] | type[Action] | None:
    module_name = f"msgs.{package}.{kind}"
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.startswith(exc.name):
            return None
        raise
    if name not in getattr(module, "__all__", ()):
        return None
    found: type[Message] | type[Service] | type[Action] = getattr(module, name)
    return found


def _case_fixed(type_name: str) -> str | None:
    """The generated type whose name differs from ``type_name`` only in case, if any."""
    package, _, rest = type_name.lower().partition("/")
    kind, _, name = rest.rpartition("/")
    if not package or not name or kind not in ("", *_KINDS) or package not in available_packages():
        return None
    for full in available_types(package):
        pkg_kind, _, found = full.rpartition("/")
        if found.lower() == name and (not kind or pkg_kind.endswith("/" + kind)):
            return full
    return None


def lookup(type_name: str) -> type[Message] | type[Service] | type[Action]:
    """The generated class for ``pkg/Name`` or ``pkg/{msg,srv,action}/Name`` (or the class
    :func:`register` made findable under that name).

    ``pkg/Name`` is searched as a message, then a service, then an action. Service and
    action parts are found too (``pkg/srv/Name_Request``, ``pkg/action/Name_Goal``).
    Raises :class:`UnknownTypeError` (a LookupError) for unknown or malformed names.
    """
    cached = _CACHE.get(type_name)
    if cached is not None:
        return cached
    found = lookup_generated(type_name)
    _CACHE[type_name] = found
    return found


_GENERATED: dict[str, type[Message] | type[Service] | type[Action]] = {}


def lookup_generated(type_name: str) -> type[Message] | type[Service] | type[Action]:
    """Like :func:`lookup`, among the types ``msgs`` generates only (not the classes
    :func:`register` made findable): what every robot's types share on a relay."""
    cached = _GENERATED.get(type_name)
    if cached is not None:
        return cached
    match = _NAME_RE.match(type_name) if isinstance(type_name, str) else None
    if match is None:
        fixed = _case_fixed(type_name) if isinstance(type_name, str) else None
        if fixed is not None:  # the right name in the wrong case: say so, not "format"
            raise UnknownTypeError(type_name, f"did you mean {fixed!r}? (type names are "
                                   "CamelCase, packages lower case)")
        raise UnknownTypeError(
            str(type_name), "expected 'package/Name' or 'package/msg|srv|action/Name'"
        )
    package, kind, name = match["pkg"], match["kind"], match["name"]
    if package in _RESERVED:
        raise UnknownTypeError(type_name, f"no generated package {package!r}")
    for candidate in (kind,) if kind else _KINDS:
        found = _find(package, candidate, name)
        if found is not None:
            _GENERATED[type_name] = found
            return found
    where = f"{package}/{kind}" if kind else package
    raise UnknownTypeError(type_name, f"no type {name!r} in {where} among the generated types")


def register(*classes: type[Message] | type[Service] | type[Action]) -> None:
    """Make classes that live outside ``msgs/`` findable by :func:`lookup`.

    Modules written by ``roslibpy-lite interface gen`` and types built at runtime by
    :mod:`msgs.dynamic` call this; the full name and the short ``pkg/Name`` are both
    registered (a message wins the short name over a service or action, as in lookup).
    """
    for cls in classes:
        full: str = cls._type
        _CACHE[full] = cls
        package, kind, name = full.split("/")
        if kind == "msg":
            _CACHE[f"{package}/{name}"] = cls
        else:
            _CACHE.setdefault(f"{package}/{name}", cls)


Find = Callable[[str], "type[Message] | type[Service] | type[Action]"]
"""A lookup by type name: :func:`lookup`, or a :class:`msgs.dynamic.TypeStore`'s."""


def lookup_message(type_name: str, among: Find | None = None) -> type[Message]:
    """Like :func:`lookup` (``among``: another lookup), for message types (including
    service and action parts)."""
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Message)):
        raise UnknownTypeError(type_name, f"{found._type} is not a message type")
    return found


Message._lookup = staticmethod(lookup_message)


def lookup_service(type_name: str, among: Find | None = None) -> type[Service]:
    """Like :func:`lookup` (``among``: another lookup), for service types."""
    if _NAME_RE.match(type_name) and type_name.count("/") == 1:
        type_name = type_name.replace("/", "/srv/")
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Service)):
        raise UnknownTypeError(type_name, f"{found._type} is not a service type")
    return found


def lookup_action(type_name: str, among: Find | None = None) -> type[Action]:
    """Like :func:`lookup` (``among``: another lookup), for action types."""
    if _NAME_RE.match(type_name) and type_name.count("/") == 1:
        type_name = type_name.replace("/", "/action/")
    found = (among or lookup)(type_name)
    if not (isinstance(found, type) and issubclass(found, Action)):
        raise UnknownTypeError(type_name, f"{found._type} is not an action type")
    return found


_MSGS_DIR = Path(__file__).resolve().parent


def available_packages() -> list[str]:
    """The packages with generated types, sorted (no module is imported)."""
    return sorted(
        d.name
        for d in _MSGS_DIR.iterdir()
        if d.name not in _RESERVED
        and _NAME_RE.match(f"{d.name}/X")
        and any((d / f"{kind}.py").is_file() for kind in _KINDS)
    )


def available_types(package: str | None = None) -> list[str]:
    """Every generated type as ``pkg/kind/Name``, sorted; imports the modules it lists.

    Messages, services and actions are listed; the parts of services and actions
    (``Name_Request``, ``Name_Goal``, ...) are reached through their namespace.
    """
    packages = available_packages() if package is None else [package]
    names: list[str] = []
    for pkg in packages:
        for kind in _KINDS:
            if not (_MSGS_DIR / pkg / f"{kind}.py").is_file():
                continue
            module = importlib.import_module(f"msgs.{pkg}.{kind}")
            for name in module.__all__:
                cls = getattr(module, name)
                if kind == "msg" or issubclass(cls, (Service, Action)):
                    names.append(cls._type)
    return sorted(names)
