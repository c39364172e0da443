"""``roslibpy-lite interface show|list|gen``: from msgs; a type msgs does not know is asked of
the bridge (rosapi's details), so the robot's own interfaces show too; ``gen`` writes typed
modules for them from the bridge's definition text."""

from __future__ import annotations

import argparse
from typing import Any

from msgs.runtime import UnknownTypeError, lookup

from .common import (
    EXIT_CONNECT,
    EXIT_NOT_FOUND,
    EXIT_OK,
    PRIMITIVES,
    CliError,
    CliSession,
    Kit,
    Out,
    with_session,
)


def _interface_class(type_name: str) -> Any:
    try:
        return lookup(type_name)
    except UnknownTypeError as exc:
        raise CliError(EXIT_NOT_FOUND, f"{exc} (see 'roslibpy-lite interface list')") from None


def _field_type(line: str, package: str) -> str | None:
    """The message type a definition line's field refers to (None for primitives/constants)."""
    body = line.split("#", 1)[0].strip()
    if not body or body == "---":
        return None
    parts = body.split()
    if len(parts) < 2 or "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
        return None  # not a field, or a constant
    base = parts[0].split("[", 1)[0].split("<", 1)[0]
    if base in PRIMITIVES:
        return None
    if "/" in base:
        pkg, _, name = base.partition("/")
        return f"{pkg}/msg/{name.rpartition('/')[2]}"
    if base == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{base}"


def _show(definition: str, package: str, depth: int, lines: list[str]) -> None:
    pad = "\t" * depth
    for line in definition.rstrip("\n").split("\n"):
        lines.append(pad + line if line else "")
        nested = _field_type(line, package)
        if nested is None:
            continue
        try:
            cls = lookup(nested)
        except UnknownTypeError:
            continue
        _show(cls._definition, nested.split("/", 1)[0], depth + 1, lines)


async def cmd_interface_show(args: argparse.Namespace, out: Out) -> int:
    """``interface show TYPE``: the definition, nested types expanded (from msgs; a type
    msgs does not generate is asked of the bridge at ``--url``)."""
    try:
        cls = _interface_class(args.type)
    except CliError as local:
        if "did you mean" in local.message or "expected 'package/" in local.message:
            raise  # a malformed or miscased name: the bridge would not know it either
        try:
            return await _show_from_bridge(args, out, local)
        except CliError as exc:
            if exc.code != EXIT_CONNECT:
                raise
            raise CliError(EXIT_NOT_FOUND, f"{local.message}; no bridge at {args.url} to ask "
                           "about the robot's own types") from None
    lines: list[str] = []
    if args.raw:
        lines = cls._definition.rstrip("\n").split("\n")
    else:
        _show(cls._definition, cls._type.split("/", 1)[0], 0, lines)
    for line in lines:
        out.line(line)
    return EXIT_OK


async def _show_from_bridge(args: argparse.Namespace, out: Out, local: CliError) -> int:
    """Print a type's fields as the bridge describes them (rosapi typedefs)."""
    kind = args.type.split("/")[1] if args.type.count("/") == 2 else "msg"
    queries = {"msg": [("message_details", "")],
               "srv": [("service_request_details", ""), ("service_response_details", "---")],
               "action": [("action_goal_details", ""), ("action_result_details", "---"),
                          ("action_feedback_details", "---")]}.get(kind, [])

    async def body(s: CliSession) -> int:
        blocks: list[tuple[str, list[dict[str, Any]]]] = []
        for service, separator in queries:
            try:
                reply = await s.rosapi(service, {"type": args.type})
            except Exception:
                reply = {}
            typedefs = reply.get("typedefs") or []
            if not typedefs:
                raise CliError(EXIT_NOT_FOUND, f"{local.message}; the bridge at {args.url} "
                               "does not know it either")
            blocks.append((separator, typedefs))
        for separator, typedefs in blocks:
            if separator:
                out.line(separator)
            by_type = {str(t.get("type", "")): t for t in typedefs}
            _typedef_lines(typedefs[0], by_type, 0, out)
        return EXIT_OK
    return await with_session(args, body)


_MSG_SPELLING = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64"}
"""rosapi names primitive types as IDL does; .msg files (and this command) spell them so."""


def _typedef_lines(typedef: dict[str, Any], by_type: dict[str, dict[str, Any]], depth: int,
                   out: Out) -> None:
    pad = "\t" * depth
    for name, value in zip(typedef.get("constnames", []), typedef.get("constvalues", []),
                           strict=False):
        out.line(f"{pad}{name} = {value}")
    for name, ftype, arraylen in zip(typedef.get("fieldnames", []),
                                     typedef.get("fieldtypes", []),
                                     typedef.get("fieldarraylen", []), strict=False):
        suffix = "[]" if arraylen == 0 else f"[{arraylen}]" if arraylen > 0 else ""
        out.line(f"{pad}{_MSG_SPELLING.get(ftype, ftype)}{suffix} {name}")
        nested = by_type.get(ftype)
        if nested is not None and depth < 16:
            _typedef_lines(nested, by_type, depth + 1, out)


BRIDGE_ONLY = "  [bridge: load_types or interface gen]"
"""How ``interface list --remote`` marks a type the bridge has and this installation lacks."""


async def cmd_interface_list(args: argparse.Namespace, out: Out) -> int:
    """``interface list [PACKAGE] [--remote]``: the types this installation knows; with
    ``--remote`` also the bridge's (at ``--url``), those only it has marked."""
    from msgs.runtime import available_packages, available_types

    local = available_types(args.package) if (
        args.package is None or args.package in available_packages()) else []
    remote: list[str] = []
    if args.remote:
        async def body(s: CliSession) -> int:
            remote.extend(str(n) for n in (await s.rosapi("interfaces")).get("interfaces", [])
                          if args.package is None or str(n).split("/")[0] == args.package)
            return EXIT_OK
        await with_session(args, body)
    if not local and not remote:
        where = " here or on the bridge" if args.remote else " (--remote asks the bridge)"
        raise CliError(EXIT_NOT_FOUND, f"unknown interface package {args.package}{where}")
    known = set(local)
    for name in sorted(known.union(remote)):
        out.line(name if name in known else name + BRIDGE_ONLY)
    return EXIT_OK


async def cmd_interface_gen(args: argparse.Namespace, out: Out) -> int:
    """``interface gen TYPE... -o DIR``: typed modules for the robot's own interfaces,
    written as msgs writes its own (definitions from the bridge at ``--url``)."""
    import re
    from pathlib import Path

    from msgs.dynamic import split
    from msgs.generator import PackageSources, render_package
    from msgs.parser import DefinitionError, parse_action, parse_message, parse_service

    target = Path(args.output)
    root_name = target.resolve().name
    if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", root_name) or root_name == "msgs":
        raise CliError(EXIT_NOT_FOUND, f"-o {args.output}: the directory becomes the Python "
                       f"package {root_name!r}, which needs an identifier other than 'msgs'")

    async def body(s: CliSession) -> int:
        packages: dict[str, PackageSources] = {}
        seen: set[str] = set()
        for name in args.types:
            try:
                reply = await s.rosapi("interface_definition", {"type": name})
            except Exception as exc:
                raise CliError(EXIT_NOT_FOUND, f"{name}: {exc}") from None
            blocks = split(reply["type"], reply["definition"])
            for i, (type_name, text) in enumerate(blocks):
                package, kind, short = type_name.split("/")
                if type_name in seen or (i and _known(type_name)):
                    continue  # types msgs has are imported from it
                seen.add(type_name)
                pkg = packages.setdefault(package, PackageSources(package))
                try:
                    if kind == "msg":
                        pkg.messages.append(parse_message(text, package, short))
                    elif kind == "srv":
                        pkg.services.append(parse_service(text, package, short))
                    else:
                        pkg.actions.append(parse_action(text, package, short))
                except DefinitionError as exc:
                    raise CliError(EXIT_NOT_FOUND, f"{type_name}: {exc}") from None

        def root(package: str) -> str:
            return root_name if package in packages else "msgs"

        written = 0
        target.mkdir(parents=True, exist_ok=True)
        init = target / "__init__.py"
        if not init.exists():
            init.write_text('"""Typed ROS 2 interfaces of the robot, written by roslibpy-lite '
                            'interface gen."""\n', encoding="utf-8")
        for package, sources in sorted(packages.items()):
            for group in (sources.messages, sources.services, sources.actions):
                group.sort(key=lambda spec: spec.name)
            directory = target / package
            directory.mkdir(exist_ok=True)
            for file_name, source in render_package(sources, root).items():
                (directory / file_name).write_text(source, encoding="utf-8")
                written += 1
        out.line(f"wrote {written} files for {', '.join(sorted(packages))} under {target} "
                 f"(import {root_name}.<package>.msg)")
        return EXIT_OK
    return await with_session(args, body)


def _known(type_name: str) -> bool:
    """Whether msgs itself generates ``type_name`` (a type loaded at runtime or written by an
    earlier ``interface gen`` is registered for lookup too, but is not importable from msgs)."""
    try:
        found = lookup(type_name)
    except UnknownTypeError:
        return False
    return found.__module__.startswith("msgs.") and not found.__module__.startswith("msgs._")


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``interface`` and its commands."""
    isub = kit.group(groups, "interface", "interface types: show (asks the bridge for types "
                     "msgs does not know), list, gen (typed modules for the robot's own types)",
                     "show,list,gen")
    p = kit.leaf(isub, "show", cmd_interface_show, "print an interface definition")
    p.add_argument("type", help="e.g. sensor_msgs/msg/Imu, mult_msgs/srv/MultFloats")
    p.add_argument("--raw", action="store_true", help="do not expand nested types")
    p = kit.leaf(isub, "list", cmd_interface_list, "list the known interface types")
    p.add_argument("package", nargs="?", help="only this package")
    p.add_argument("-r", "--remote", action="store_true",
                   help="add the bridge's types (at --url); those only it has are marked "
                        "(load them with load_types, or interface gen)")
    p = kit.leaf(isub, "gen", cmd_interface_gen,
                 "write typed modules for the robot's own types (as msgs generates them)")
    p.add_argument("types", nargs="+", metavar="TYPE", help="e.g. my_robot_msgs/msg/Status")
    p.add_argument("-o", "--output", required=True,
                   help="directory to write; it becomes a Python package of that name")
