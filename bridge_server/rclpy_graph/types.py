"""ROS interface types on rclpy: type names resolved to rclpy classes.

Type names and the error roots are ROS-free and live in :mod:`rosbridge_core.interfaces`
(re-exported here); this module adds what needs the installed ROS packages.

API
---
``parse_type_name(name, kind) -> TypeName``
    Split and validate a type string (no import). ``kind`` is the kind the
    caller expects (``"msg"``, ``"srv"`` or ``"action"``); a name that spells a
    different kind is a :class:`TypeNameError`.
``resolve_message(name) -> type``
    The rclpy message class for ``std_msgs/String`` or ``std_msgs/msg/String``.
``resolve_service(name) -> type``
    The rclpy service class (it has ``.Request`` and ``.Response``).
``resolve_action(name) -> type``
    The rclpy action class (``.Goal``, ``.Result``, ``.Feedback``, ``.Impl``).
``type_name_of(cls) -> str``
    Canonical name of a message, service or action class, e.g.
    ``"std_msgs/msg/String"``, ``"std_srvs/srv/SetBool"``; for the request
    class of a service ``"std_srvs/srv/SetBool_Request"``.
``canonical_name(name, kind) -> str``
    The canonical spelling of a valid type string, without importing it.

Resolution only imports packages that the ament index lists as providing
that interface (``share/ament_index/resource_index/rosidl_interfaces/<pkg>``
under ``$AMENT_PREFIX_PATH`` and the interpreter prefix), so a client can
never make the bridge import an arbitrary Python module. Successful lookups
are cached; the cache is thread safe (a race only costs a second import).

Errors are :mod:`rosbridge_core.interfaces`' (``TypeNameError``, ``UnknownTypeError``).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from typing import Any

from rosbridge_core.interfaces import (
    KINDS,
    TYPE_RE,
    BridgeError,
    Kind,
    TypeName,
    TypeNameError,
    UnknownTypeError,
    canonical_name,
    parse_type_name,
)

__all__ = [
    "BridgeError",
    "Kind",
    "TypeName",
    "TypeNameError",
    "UnknownTypeError",
    "canonical_name",
    "parse_type_name",
    "resolve_action",
    "resolve_message",
    "resolve_service",
    "type_name_of",
]

def _index_dirs() -> list[Path]:
    """Directories that hold ``rosidl_interfaces`` ament index entries."""
    prefixes: list[str] = []
    env = os.environ.get("AMENT_PREFIX_PATH", "")
    prefixes.extend(p for p in env.split(os.pathsep) if p)
    for p in (sys.prefix, sys.base_prefix):
        if p not in prefixes:
            prefixes.append(p)
    dirs = []
    for p in prefixes:
        d = Path(p) / "share" / "ament_index" / "resource_index" / "rosidl_interfaces"
        if d.is_dir():
            dirs.append(d)
    return dirs


def installed_interfaces() -> list[str]:
    """Every interface type the ament index lists (``pkg/msg/Name``, ``pkg/srv/...``,
    ``pkg/action/...``), sorted: what this bridge can resolve."""
    found: set[str] = set()
    for d in _index_dirs():
        for entry in d.iterdir():
            try:
                lines = entry.read_text(encoding="utf-8").splitlines()
            except OSError:
                continue
            for line in lines:
                kind, _, file_name = line.strip().partition("/")
                name, _, _ext = file_name.partition(".")
                if kind in ("msg", "srv", "action") and TYPE_RE.match(name):
                    found.add(f"{entry.name}/{kind}/{name}")
    return sorted(found)


def _index_lists(tn: TypeName) -> bool | None:
    """Whether the ament index lists ``tn``; ``None`` if no index is present at all."""
    dirs = _index_dirs()
    if not dirs:
        return None
    wanted = {f"{tn.kind}/{tn.type}.idl", f"{tn.kind}/{tn.type}.{tn.kind}"}
    for d in dirs:
        entry = d / tn.package
        if entry.is_file():
            try:
                lines = entry.read_text(encoding="utf-8").splitlines()
            except OSError:
                continue
            if wanted.intersection(line.strip() for line in lines):
                return True
    return False


_cache: dict[TypeName, type[Any]] = {}


def _resolve(name: object, kind: Kind) -> type[Any]:
    tn = parse_type_name(name, kind)
    cls = _cache.get(tn)
    if cls is not None:
        return cls
    listed = _index_lists(tn)
    shown = name if isinstance(name, str) else str(tn)
    if listed is False:
        raise UnknownTypeError(shown, f"no installed package provides {tn}")
    try:
        module = importlib.import_module(f"{tn.package}.{kind}")
    except ImportError as exc:
        raise UnknownTypeError(shown, f"cannot import {tn.package}.{kind} ({exc})") from None
    found = getattr(module, tn.type, None)
    if not isinstance(found, type) or not _looks_like(found, kind):
        raise UnknownTypeError(shown, f"{tn.package}.{kind} has no {kind} type {tn.type!r}")
    _cache[tn] = found
    return found


def _looks_like(cls: type[Any], kind: Kind) -> bool:
    if kind == "msg":
        return hasattr(cls, "get_fields_and_field_types") and hasattr(cls, "SLOT_TYPES")
    if kind == "srv":
        return hasattr(cls, "Request") and hasattr(cls, "Response")
    return hasattr(cls, "Goal") and hasattr(cls, "Result") and hasattr(cls, "Feedback")


def resolve_message(name: object) -> type[Any]:
    """Return the rclpy message class for ``pkg/Type`` or ``pkg/msg/Type``.

    Raises :class:`TypeNameError` for a malformed string and
    :class:`UnknownTypeError` for a well-formed name that is not installed.
    """
    return _resolve(name, "msg")


def resolve_service(name: object) -> type[Any]:
    """Return the rclpy service class (with ``.Request``/``.Response``) for ``pkg/[srv/]Type``."""
    return _resolve(name, "srv")


def resolve_action(name: object) -> type[Any]:
    """Return the rclpy action class (``.Goal``, ``.Result``, ``.Feedback``) for an action name."""
    return _resolve(name, "action")


def type_name_of(cls: type[Any]) -> str:
    """Canonical ``pkg/<kind>/Type`` name of an rclpy message, service or action class.

    Nested classes keep their rclpy names, e.g. ``std_srvs/srv/SetBool_Request``
    and ``test_msgs/action/Fibonacci_Goal``.
    """
    parts = getattr(cls, "__module__", "").split(".")
    if len(parts) < 2 or parts[1] not in KINDS:
        raise TypeError(f"{cls!r} is not an rclpy interface class")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"
