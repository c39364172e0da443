"""``roslibpy-lite interface show|list`` (from msgs, no bridge)."""

from __future__ import annotations

import argparse
from typing import Any

from msgs.runtime import UnknownTypeError, lookup

from .common import (
    EXIT_NOT_FOUND,
    EXIT_OK,
    PRIMITIVES,
    CliError,
    Kit,
    Out,
    Parser,
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
    """``interface show TYPE``: the definition, nested types expanded (from msgs, no bridge)."""
    cls = _interface_class(args.type)
    lines: list[str] = []
    if args.raw:
        lines = cls._definition.rstrip("\n").split("\n")
    else:
        _show(cls._definition, cls._type.split("/", 1)[0], 0, lines)
    for line in lines:
        out.line(line)
    return EXIT_OK


async def cmd_interface_list(args: argparse.Namespace, out: Out) -> int:
    """``interface list [PACKAGE]``: the types this installation knows."""
    from msgs.runtime import available_packages, available_types

    if args.package is not None and args.package not in available_packages():
        raise CliError(EXIT_NOT_FOUND, f"unknown interface package {args.package}")
    for name in available_types(args.package):
        out.line(name)
    return EXIT_OK


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``interface`` and its commands."""
    interface = groups.add_parser("interface", help="interface types: show, list (no bridge)")
    isub = interface.add_subparsers(dest="command", metavar="{show,list}", parser_class=Parser)
    isub.required = True
    p = kit.leaf(isub, "show", cmd_interface_show, "print an interface definition")
    p.add_argument("type", help="e.g. sensor_msgs/msg/Imu, mult_msgs/srv/MultFloats")
    p.add_argument("--raw", action="store_true", help="do not expand nested types")
    p = kit.leaf(isub, "list", cmd_interface_list, "list the known interface types")
    p.add_argument("package", nargs="?", help="only this package")
