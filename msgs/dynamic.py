"""Interface types built at runtime from their definition text (a robot's own types).

A robot always has interfaces of its own that ``msgs`` does not generate. Their
definition text, in the ``ros2msg`` layout rosbag2 stores in MCAP schemas (the
type's own text, then each dependency after a line of 80 ``=`` and a line
``MSG: pkg/msg/Name``), is all it takes to build the same typed classes the
generator writes::

    Status = msgs.dynamic.load("my_robot_msgs/msg/Status", text)
    msgs.runtime.lookup("my_robot_msgs/msg/Status") is Status   # True

The text comes from the bridge (``/rosapi/interface_definition``, or the
``typedefs_full_text`` of ``/rosapi/topics_and_raw_types``), from an MCAP schema, or
from a ``.msg``/``.srv``/``.action`` file. The classes are rendered by
:mod:`msgs.generator` itself, so they validate, convert and decode CDR exactly as
generated ones do; they live in modules ``msgs._loaded.<pkg>.<kind>``. Types that
``msgs`` already has are taken from it, not redefined. A malformed text raises
:class:`~msgs.parser.DefinitionError` naming the type, the line and the reason.

:func:`full_text` gives the same layout for any known message type (what a
recorder writes as the schema of a topic).
"""

from __future__ import annotations

import re
import sys
import threading
import types
from collections.abc import Iterable

from .generator import SHADOWING_NAMES, render_module
from .parser import (
    ActionSpec,
    DefinitionError,
    MessageSpec,
    ServiceSpec,
    parse_action,
    parse_message,
    parse_service,
)
from .runtime import Action, Message, Service, UnknownTypeError, available_packages, lookup

__all__ = ["DELIMITER", "full_text", "load", "split"]

#: The line between two definitions in the ``ros2msg`` layout.
DELIMITER = "=" * 80
_ROOT = "msgs._loaded"
_NAME = re.compile(r"^(?P<pkg>[a-z][a-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?"
                   r"(?P<name>[A-Z][A-Za-z0-9_]*)$")
_LOCK = threading.Lock()

Interface = type[Message] | type[Service] | type[Action]


def _parts(type_name: str) -> tuple[str, str, str]:
    match = _NAME.match(type_name.strip())
    if match is None:
        raise UnknownTypeError(type_name,
                               "expected 'package/Name' or 'package/msg|srv|action/Name'")
    return match["pkg"], match["kind"] or "msg", match["name"]


def split(type_name: str, text: str) -> list[tuple[str, str]]:
    """``(full type name, definition text)`` of the type, then of each ``MSG:`` dependency."""
    package, kind, name = _parts(type_name)
    blocks: list[tuple[str, list[str]]] = [(f"{package}/{kind}/{name}", [])]
    lines = text.splitlines(keepends=True)
    i = 0
    while i < len(lines):
        line = lines[i]
        follows = lines[i + 1].strip() if i + 1 < len(lines) else ""
        if line.strip() == DELIMITER and follows.startswith("MSG:"):
            dep_pkg, dep_kind, dep_name = _parts(follows[4:].strip())
            if dep_kind != "msg":
                raise DefinitionError(f"<{type_name} definition>", i + 2,
                                      f"dependency {follows[4:].strip()} is not a message")
            blocks.append((f"{dep_pkg}/msg/{dep_name}", []))
            i += 2
            continue
        blocks[-1][1].append(line)
        i += 1
    return [(name, "".join(body)) for name, body in blocks]


def _known(type_name: str) -> Interface | None:
    try:
        return lookup(type_name)
    except UnknownTypeError:
        return None


def load(type_name: str, text: str) -> Interface:
    """The class of ``type_name`` (message, service or action) built from ``text``.

    ``text`` is the type's definition followed by its dependencies (``ros2msg``
    layout); dependencies that ``msgs`` knows may be left out. Every class built is
    registered, so :func:`msgs.runtime.lookup` and CDR decoding find it by name.
    Loading a type again returns the class already built.
    """
    with _LOCK:
        return _load(type_name, text)


def _load(type_name: str, text: str) -> Interface:
    blocks = split(type_name, text)
    top_name, top_text = blocks[0]
    found = _known(top_name)
    if found is not None:
        return found
    package, kind, name = top_name.split("/")
    file = f"<{top_name} definition>"
    messages: dict[str, MessageSpec] = {}
    for dep_name, dep_text in blocks[1:]:
        if dep_name in messages or _known(dep_name) is not None:
            continue
        dep_pkg, _, dep_short = dep_name.split("/")
        messages[dep_name] = parse_message(dep_text, dep_pkg, dep_short,
                                           file=f"<{dep_name} definition>")
    top: MessageSpec | ServiceSpec | ActionSpec
    if kind == "msg":
        top = messages[top_name] = parse_message(top_text, package, name, file=file)
        parts: tuple[MessageSpec, ...] = ()
    elif kind == "srv":
        top = parse_service(top_text, package, name, file=file)
        parts = (top.request, top.response)
    else:
        top = parse_action(top_text, package, name, file=file)
        parts = (top.goal, top.result, top.feedback)
    _check(top_name, [*messages.values(), *parts], set(messages))
    for pkg in _package_order(messages.values()):
        specs = [m for m in messages.values() if m.package == pkg]
        _define(pkg, "msg", specs, (), top_name)
    if kind != "msg":
        assert isinstance(top, ServiceSpec | ActionSpec)
        _define(package, kind, list(parts), (top,), top_name)
    return lookup(top_name)


def _check(top_name: str, specs: Iterable[MessageSpec], new: set[str]) -> None:
    """Every nested type is defined in the text or known; no field shadows a builtin."""
    generated = set(available_packages())
    for spec in specs:
        if spec.package in generated and spec.type_name in new:
            raise DefinitionError(
                spec.file, 1, f"{spec.type_name} is not among the generated {spec.package} "
                "types of msgs, and a package msgs generates cannot take types at runtime "
                "(regenerate msgs with this definition)")
        for f in spec.fields:
            if f.name in SHADOWING_NAMES:
                raise DefinitionError(spec.file, f.line,
                                      f"field name {f.name!r} is not supported")
            if f.type.is_primitive:
                continue
            nested = f.type.message_type
            if nested not in new and _known(nested) is None:
                raise DefinitionError(
                    spec.file, f.line, f"unknown type {nested}: neither in the definition "
                    f"text of {top_name} nor among the types msgs knows")


def _package_order(specs: Iterable[MessageSpec]) -> list[str]:
    """Packages so that each comes after the packages its new types refer to."""
    needs: dict[str, set[str]] = {}
    for spec in specs:
        deps = needs.setdefault(spec.package, set())
        deps.update(f.type.package for f in spec.fields
                    if f.type.package is not None and f.type.package != spec.package)
    ordered: list[str] = []
    visiting: set[str] = set()

    def visit(pkg: str) -> None:
        if pkg in ordered or pkg not in needs or pkg in visiting:
            return
        visiting.add(pkg)
        for dep in sorted(needs[pkg]):
            visit(dep)
        ordered.append(pkg)

    for pkg in sorted(needs):
        visit(pkg)
    return ordered


def _root(package: str) -> str:
    return "msgs" if package in available_packages() else _ROOT


def _module(package: str, kind: str) -> types.ModuleType:
    """``msgs._loaded.<package>.<kind>``, created (with its parents) on first use."""
    path = [*_ROOT.split("."), package, kind]
    parent: types.ModuleType | None = None
    for depth in range(1, len(path) + 1):
        name = ".".join(path[:depth])
        module = sys.modules.get(name)
        if module is None:
            module = types.ModuleType(name, "Interface types loaded at runtime (msgs.dynamic).")
            module.__dict__["__all__"] = []
            sys.modules[name] = module
            if parent is not None:
                setattr(parent, path[depth - 1], module)
        parent = module
    assert parent is not None
    return parent


def _define(package: str, kind: str, messages: list[MessageSpec],
            namespaces: tuple[ServiceSpec | ActionSpec, ...], top_name: str) -> None:
    if kind == "msg":
        _module(package, "msg")  # the module the others import their nested types from
    module = _module(package, kind)
    source = render_module(package, kind, messages, namespaces, _root)
    before = list(module.__dict__.get("__all__", []))
    code = compile(source, f"<{top_name} definition, {package}/{kind}>", "exec")
    # The generator's output: every name in it passed the parser's identifier rules and
    # every text and default is a literal it wrote, so a definition cannot inject code.
    exec(code, module.__dict__)
    module.__dict__["__all__"] = sorted(set(before) | set(module.__dict__["__all__"]))


def full_text(type_name: str) -> str:
    """The ``ros2msg`` text of a known message type: its definition, then its dependencies'."""
    cls = lookup(type_name)
    if not (isinstance(cls, type) and issubclass(cls, Message)):
        raise UnknownTypeError(type_name, "not a message type")
    parts = [cls._definition.rstrip("\n")]
    seen = {cls._type}
    todo = [cls]
    while todo:
        current = todo.pop(0)
        for idl in current._fields_and_types.values():
            nested = _nested_name(idl)
            if nested is None or nested in seen:
                continue
            seen.add(nested)
            dep = lookup(nested)
            assert isinstance(dep, type) and issubclass(dep, Message)
            parts.append(f"{DELIMITER}\nMSG: {dep._type}\n{dep._definition.rstrip(chr(10))}")
            todo.append(dep)
    return "\n".join(parts) + "\n"


def _nested_name(idl: str) -> str | None:
    """``pkg/msg/Name`` of a field's message type (None for primitives)."""
    base = idl
    if base.startswith("sequence<"):
        base = base[len("sequence<"):].split(",")[0].rstrip(">").strip()
    base = base.split("[")[0]
    if "/" not in base:
        return None
    package, name = base.split("/")[0], base.split("/")[-1]
    return f"{package}/msg/{name}"
