"""Interface types built at runtime from their definition text (a robot's own types).

A robot always has interfaces of its own that ``msgs`` does not generate. Their
definition text, in the ``ros2msg`` layout rosbag2 stores in MCAP schemas (the
type's own text, then each dependency after a line of 80 ``=`` and a line
``MSG: pkg/msg/Name``), is all it takes to build the same typed classes the
generator writes::

    Status = msgs.dynamic.load("my_robot_msgs/msg/Status", text)
    msgs.runtime.lookup("my_robot_msgs/msg/Status") is Status   # True

Where each definition lives is a :class:`TypeStore`. :data:`DEFAULT`, the one
:func:`load` uses unless told otherwise, is process-wide: its classes are registered
(:func:`msgs.runtime.lookup` finds them) and the first definition of a name wins, which
is what a client wants (its bag reader, its robot's types, the command line). A program
that serves many robots (the relay) gives each robot a store of its own: two robots may
define the same name differently and each gets its own class; the store's classes are
found by name only through the store (their nested types too, for checking, converting
and CDR), a store may cap the size of a definition and the number of its types
(:class:`LimitError`), and its classes go (garbage) once the store is closed and nothing
else holds them. Types ``msgs`` generates are shared by every store. Loading costs the
parse once per (type name, text): every store keeps what it built by a digest of both,
and a text it has seen is not split or parsed again::

    robot1 = msgs.dynamic.TypeStore("robot robot1", max_types=1000)
    Status = robot1.load("my_robot_msgs/msg/Status", text)
    robot1.lookup("my_robot_msgs/msg/Status") is Status   # True; runtime.lookup: unknown

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

import hashlib
import itertools
import re
import sys
import threading
import types
from collections.abc import Callable, Iterable

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
from .runtime import (
    Action,
    Message,
    Service,
    UnknownTypeError,
    available_packages,
    lookup,
    lookup_action,
    lookup_generated,
    lookup_message,
    lookup_service,
)

__all__ = ["DEFAULT", "DELIMITER", "LimitError", "TypeStore", "full_text", "load", "split"]

#: The line between two definitions in the ``ros2msg`` layout.
DELIMITER = "=" * 80
_ROOT = "msgs._loaded"
_NAME = re.compile(r"^(?P<pkg>[a-z][a-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?"
                   r"(?P<name>[A-Z][A-Za-z0-9_]*)$")
_LOCK = threading.Lock()  # sys.modules and every store's tables
_STORE_IDS = itertools.count(1)

Interface = type[Message] | type[Service] | type[Action]


class LimitError(DefinitionError):
    """A definition a :class:`TypeStore` refuses for one of its limits: ``limit`` is the
    limit's name (``max_definition_bytes``, ``max_types``), ``allowed`` its value, ``got``
    what the definition would have made of ``what`` it measures."""

    def __init__(self, type_name: str, limit: str, allowed: int, got: int, what: str) -> None:
        self.type_name, self.limit, self.allowed, self.got = type_name, limit, allowed, got
        self.what = what
        super().__init__(f"<{type_name} definition>", 1,
                         f"{what} ({got}) is over {limit} ({allowed})")


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


class TypeStore:
    """A namespace of interface types built from definition texts (see the module's text).

    ``name`` says whose types they are in errors (``"robot robot1"``). ``max_types`` caps
    the messages, services and actions the store defines (a service's or action's parts
    are not counted apart), ``max_definition_bytes`` the UTF-8 size of one definition text
    given to :meth:`load`; ``None``: no limit. A definition over either raises
    :class:`LimitError` before it is parsed, and nothing of it is defined.
    """

    def __init__(self, name: str, *, max_types: int | None = None,
                 max_definition_bytes: int | None = None) -> None:
        self.name = name
        self.max_types = max_types
        self.max_definition_bytes = max_definition_bytes
        self.closed = False
        self._root = f"{_ROOT}._{next(_STORE_IDS)}"
        self._types: dict[str, Interface] = {}  # full and short (pkg/Name) names -> class
        self._defined: set[str] = set()  # full names of the messages, services, actions
        self._built: dict[bytes, Interface] = {}  # digest of (type name, text) -> class

    def __len__(self) -> int:
        """How many messages, services and actions the store defined."""
        return len(self._defined)

    def __repr__(self) -> str:
        return f"<TypeStore {self.name}: {len(self)} types>"

    # -- lookup ------------------------------------------------------------------------------

    def lookup(self, type_name: str) -> Interface:
        """The store's class of ``type_name``, else the type ``msgs`` generates (as
        :func:`msgs.runtime.lookup` spells names); :class:`UnknownTypeError` if neither."""
        found = self._types.get(type_name)
        return found if found is not None else lookup_generated(type_name)

    def lookup_message(self, type_name: str) -> type[Message]:
        """:meth:`lookup` for message types (a service's or action's parts too)."""
        return lookup_message(type_name, self.lookup)

    def lookup_service(self, type_name: str) -> type[Service]:
        """:meth:`lookup` for service types."""
        return lookup_service(type_name, self.lookup)

    def lookup_action(self, type_name: str) -> type[Action]:
        """:meth:`lookup` for action types."""
        return lookup_action(type_name, self.lookup)

    def _known(self, type_name: str) -> Interface | None:
        try:
            return self.lookup(type_name)
        except UnknownTypeError:
            return None

    def full_text(self, type_name: str) -> str:
        """The ``ros2msg`` text of a message type of the store (or generated)."""
        return _full_text(self.lookup_message(type_name))

    # -- loading -----------------------------------------------------------------------------

    def load(self, type_name: str, text: str) -> Interface:
        """The class of ``type_name`` (message, service or action) built from ``text``.

        ``text`` is the type's definition followed by its dependencies (``ros2msg``
        layout); dependencies that ``msgs`` generates may be left out. A type the store
        has (or ``msgs`` generates) is not defined again: its class is returned. The same
        (name, text) again costs a digest of the text: it is neither split nor parsed.
        Raises :class:`~msgs.parser.DefinitionError` (:class:`LimitError` for a limit).
        """
        with _LOCK:
            if self.closed:
                raise DefinitionError(f"<{type_name} definition>", 1,
                                      f"the types of {self.name} were released")
            self._check_size(type_name, text)
            key = hashlib.blake2b(f"{type_name}\n{text}".encode(), digest_size=16).digest()
            found = self._built.get(key)
            if found is None:
                found = self._build(type_name, text)
                self._built[key] = found
            return found

    def _check_size(self, type_name: str, text: str) -> None:
        limit = self.max_definition_bytes
        if limit is None or len(text) * 4 <= limit:  # a character is at most 4 bytes
            return
        size = len(text.encode())
        if size > limit:
            raise LimitError(type_name, "max_definition_bytes", limit, size,
                             "the definition's size in bytes")

    def _build(self, type_name: str, text: str) -> Interface:
        blocks = split(type_name, text)
        top_name, top_text = blocks[0]
        found = self._known(top_name)
        if found is not None:
            return found
        package, kind, name = top_name.split("/")
        file = f"<{top_name} definition>"
        messages: dict[str, MessageSpec] = {}
        for dep_name, dep_text in blocks[1:]:
            if dep_name in messages or self._known(dep_name) is not None:
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
        _check(top_name, [*messages.values(), *parts], set(messages), self._known)
        new = len(messages) + (kind != "msg")
        if self.max_types is not None and len(self) + new > self.max_types:
            raise LimitError(top_name, "max_types", self.max_types, len(self) + new,
                             f"the number of types of {self.name} with this one's")
        for pkg in _package_order(messages.values()):
            specs = [m for m in messages.values() if m.package == pkg]
            self._define(pkg, "msg", specs, (), top_name)
        if kind != "msg":
            assert isinstance(top, ServiceSpec | ActionSpec)
            self._define(package, kind, list(parts), (top,), top_name)
        self._defined.update(messages)
        if kind != "msg":
            self._defined.add(top_name)
        return self.lookup(top_name)

    def _package_root(self, package: str) -> str:
        return "msgs" if package in available_packages() else self._root

    def _define(self, package: str, kind: str, messages: list[MessageSpec],
                namespaces: tuple[ServiceSpec | ActionSpec, ...], top_name: str) -> None:
        if kind == "msg":
            _module(self._root, package, "msg")  # the one the others import nested types from
        module = _module(self._root, package, kind)
        source = render_module(package, kind, messages, namespaces, self._package_root,
                               register=False)
        names = _run(module, source, top_name, package, kind)
        found = self.lookup_message
        for cls in (getattr(module, n) for n in names):
            if issubclass(cls, Message):  # its nested types are this store's
                type.__setattr__(cls, "_lookup", staticmethod(found))
            full: str = cls._type
            self._types[full] = cls
            short = "/".join(full.split("/")[::2])
            if full.split("/")[1] == "msg":
                self._types[short] = cls
            else:
                self._types.setdefault(short, cls)

    def close(self) -> None:
        """Forget the store's modules (``sys.modules``) and refuse further loads; its
        classes go once nothing holds them (a class keeps its store, for its nested types)."""
        with _LOCK:
            self.closed = True
            self._built.clear()
            for name in [m for m in sys.modules if m == self._root
                         or m.startswith(self._root + ".")]:
                del sys.modules[name]
            parent = sys.modules.get(_ROOT)
            if parent is not None:
                parent.__dict__.pop(self._root.rsplit(".", 1)[1], None)


class _ProcessStore(TypeStore):
    """:data:`DEFAULT`: classes registered with :func:`msgs.runtime.register` (found by
    :func:`msgs.runtime.lookup`), in modules ``msgs._loaded.<pkg>.<kind>``."""

    def __init__(self) -> None:
        super().__init__("this process")
        self._root = _ROOT

    def lookup(self, type_name: str) -> Interface:
        """:func:`msgs.runtime.lookup`: generated, registered or loaded here."""
        return lookup(type_name)

    def _define(self, package: str, kind: str, messages: list[MessageSpec],
                namespaces: tuple[ServiceSpec | ActionSpec, ...], top_name: str) -> None:
        if kind == "msg":
            _module(_ROOT, package, "msg")
        module = _module(_ROOT, package, kind)
        source = render_module(package, kind, messages, namespaces, self._package_root)
        _run(module, source, top_name, package, kind)  # registers its classes

    def close(self) -> None:
        """The process-wide store stays."""


DEFAULT: TypeStore = _ProcessStore()
"""The process-wide store: what :func:`load` and :func:`full_text` use by default."""


def load(type_name: str, text: str, store: TypeStore | None = None) -> Interface:
    """The class of ``type_name`` (message, service or action) built from ``text`` in
    ``store`` (default :data:`DEFAULT`): see :meth:`TypeStore.load`.

    In :data:`DEFAULT` every class built is registered, so :func:`msgs.runtime.lookup`
    and CDR decoding find it by name; loading a type again returns the class already built.
    """
    return (store or DEFAULT).load(type_name, text)


def _check(top_name: str, specs: Iterable[MessageSpec], new: set[str],
           known: Callable[[str], Interface | None]) -> None:
    """Every nested type is defined in the text or ``known``; no field shadows a builtin."""
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
            if nested not in new and known(nested) is None:
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


def _module(root: str, package: str, kind: str) -> types.ModuleType:
    """``<root>.<package>.<kind>``, created (with its parents) on first use."""
    path = [*root.split("."), package, kind]
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


def _run(module: types.ModuleType, source: str, top_name: str, package: str, kind: str
         ) -> list[str]:
    """Run the generator's ``source`` in ``module``: the names it defined."""
    before = list(module.__dict__.get("__all__", []))
    code = compile(source, f"<{top_name} definition, {package}/{kind}>", "exec")
    # The generator's output: every name in it passed the parser's identifier rules and
    # every text and default is a literal it wrote, so a definition cannot inject code.
    exec(code, module.__dict__)
    added: list[str] = module.__dict__["__all__"]
    module.__dict__["__all__"] = sorted(set(before) | set(added))
    return added


def full_text(type_name: str | type[Message], store: TypeStore | None = None) -> str:
    """The ``ros2msg`` text of a message type: its definition, then its dependencies'.

    ``type_name`` is a name (found in ``store``, default :data:`DEFAULT`) or the class.
    """
    if isinstance(type_name, str):
        return (store or DEFAULT).full_text(type_name)
    return _full_text(type_name)


def _full_text(cls: type[Message]) -> str:
    """:func:`full_text` of a class (its nested types found as the class finds them)."""
    if not (isinstance(cls, type) and issubclass(cls, Message)):
        raise UnknownTypeError(str(getattr(cls, "_type", cls)), "not a message type")
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
            dep = current._lookup(nested)
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
