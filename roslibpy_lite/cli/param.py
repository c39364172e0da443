"""``roslibpy-lite param list|get|set|describe|dump|load|delete``, as ``ros2 param`` does them.

Each command calls the node's own parameter services through the bridge
(``/node/list_parameters``, ``get_parameters``, ``set_parameters``,
``describe_parameters``; ``rcl_interfaces/srv/*``), as ``ros2 param`` does, so values
keep their ROS types (an integer stays an integer, a double array a double array) and
``describe`` has the node's descriptors. A bridge with roles lets a token do it only with
``params`` on ``/node:*``; a refusal is printed as the bridge words it (exit 6).
Output is ``ros2 param``'s, line for line (see :mod:`.paramvalue`).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from msgs.rcl_interfaces.srv import SetParameters

from ..exceptions import RemoteError, RosTimeoutError
from .common import (
    EXIT_NOT_FOUND,
    EXIT_OK,
    EXIT_REMOTE,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    hidden,
    node_wait_parser,
    with_session,
)
from .format import ArgumentError, have_yaml
from .paramvalue import (
    NOT_SET,
    dump_yaml,
    get_line,
    guess_value,
    parameters_from_yaml,
    to_python,
    type_name,
)

_TYPES = {
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
    "describe_parameters": "rcl_interfaces/srv/DescribeParameters",
}
"""A node's parameter services (``/node/<name>``) this module calls, and their types."""


def _need_yaml(command: str) -> None:
    if not have_yaml():
        raise CliError(EXIT_USAGE, f"param {command} reads and writes ros2's YAML: it needs "
                                   "PyYAML (pip install pyyaml, or the wheel's [cli] extra)")


async def _call(s: CliSession, node: str, service: str, request: dict[str, Any]
                ) -> dict[str, Any]:
    """Call the node's parameter service ``service`` (``get_parameters``)."""
    return await s.node_call(node, service, _TYPES[service], request)


async def _names(s: CliSession, node: str, prefixes: list[str] | None = None) -> list[str]:
    """The node's parameter names, sorted (``list_parameters``, every depth)."""
    reply = await _call(s, node, "list_parameters", {"prefixes": prefixes or [], "depth": 0})
    return sorted(str(n) for n in reply.get("result", {}).get("names", []))


async def _get(s: CliSession, node: str, names: list[str]) -> list[dict[str, Any]]:
    """The ParameterValues of ``names`` (empty when the node has not declared one)."""
    return list((await _call(s, node, "get_parameters", {"names": names})).get("values", []))


async def _set(s: CliSession, node: str, params: list[tuple[str, dict[str, Any]]]
               ) -> list[dict[str, Any]]:
    """Set each (name, ParameterValue); the node's result for each, in order."""
    given = {"parameters": [{"name": n, "value": v} for n, v in params]}
    request = SetParameters.Request.from_json(given).to_json()  # every field, defaults too
    return list((await _call(s, node, "set_parameters", request)).get("results", []))


def _result_line(result: dict[str, Any], ok: str, failed: str) -> tuple[bool, str]:
    good = bool(result.get("successful"))
    reason = str(result.get("reason", ""))
    text = ok if good else failed
    return good, f"{text}: {reason}" if reason else text


async def cmd_param_list(args: argparse.Namespace, out: Out) -> int:
    """``param list [NODE]``: ``/node:`` and its parameter names, two spaces in, per node."""
    try:
        pattern = re.compile(args.filter) if args.filter is not None else None
    except re.error as exc:
        raise CliError(EXIT_USAGE, f"--filter {args.filter!r} is not a regular expression: "
                                   f"{exc}") from None

    async def body(s: CliSession) -> int:
        if args.node_name:
            nodes = [await s.node(args.node_name, args.wait)]
        else:
            served = set((await s.rosapi("services")).get("services", []))
            nodes = [n for n in await s.ros.graph.node_names(timeout=s.timeout)
                     if f"{n}/list_parameters" in served
                     and (args.include_hidden_nodes or not hidden(n))]
        code = EXIT_OK
        for node in nodes:
            try:
                names = await _names(s, node, args.param_prefixes)
            except (RemoteError, RosTimeoutError) as exc:  # a node gone meanwhile, say
                if args.node_name:
                    raise
                print(f"Exception while calling service of node '{node}': {exc}",
                      file=sys.stderr, flush=True)
                code = EXIT_REMOTE
                continue
            if pattern is not None:
                names = [n for n in names if pattern.match(n)]
            types: dict[str, str] = {}
            if args.param_type and names:
                reply = await _call(s, node, "describe_parameters", {"names": names})
                types = {str(d["name"]): type_name(int(d.get("type", NOT_SET)))
                         for d in reply.get("descriptors", [])}
            if not args.node_name and names:
                out.line(f"{node}:")
            for name in names:
                out.line(f"  {name} (type: {types.get(name, 'not set')})" if args.param_type
                         else f"  {name}")
        return code
    return await with_session(args, body)


async def cmd_param_get(args: argparse.Namespace, out: Out) -> int:
    """``param get NODE NAME``: ``Integer value is: 5`` (``--hide-type``: ``5``)."""
    async def body(s: CliSession) -> int:
        node = await s.node(args.node_name, args.wait)
        values = await _get(s, node, [args.parameter_name])
        if not values:
            raise CliError(EXIT_NOT_FOUND, f"Parameter not set: {node} has no parameter "
                                           f"{args.parameter_name}")
        out.line(get_line(values[0], args.hide_type))
        return EXIT_OK
    return await with_session(args, body)


async def _set_one(args: argparse.Namespace, out: Out, value: dict[str, Any], ok: str,
                   failed: str) -> int:
    async def body(s: CliSession) -> int:
        node = await s.node(args.node_name, args.wait)
        results = await _set(s, node, [(args.parameter_name, value)])
        if len(results) != 1:
            raise CliError(EXIT_REMOTE, f"{node}/set_parameters answered {len(results)} "
                                        "results for one parameter")
        good, line = _result_line(results[0], ok, failed)
        if good:
            out.line(line)
            return EXIT_OK
        print(line, file=sys.stderr, flush=True)
        return EXIT_REMOTE
    return await with_session(args, body)


async def cmd_param_set(args: argparse.Namespace, out: Out) -> int:
    """``param set NODE NAME VALUE``: VALUE typed as ros2 types it (``5`` an integer)."""
    _need_yaml("set")
    return await _set_one(args, out, guess_value(args.value), "Set parameter successful",
                          "Setting parameter failed")


async def cmd_param_delete(args: argparse.Namespace, out: Out) -> int:
    """``param delete NODE NAME``: undeclare it (the node must allow that)."""
    return await _set_one(args, out, {"type": NOT_SET}, "Deleted parameter successfully",
                          "Deleting parameter failed")


def _describe_lines(d: dict[str, Any]) -> list[str]:
    """``ros2 param describe``'s lines for one ParameterDescriptor."""
    lines = [f"Parameter name: {d.get('name', '')}",
             f"  Type: {type_name(int(d.get('type', NOT_SET)))}"]
    if d.get("description"):
        lines.append(f"  Description: {d['description']}")
    lines.append("  Constraints:")
    if d.get("read_only"):
        lines.append("    Read only: true")
    ranges: list[tuple[dict[str, Any], Callable[[Any], float | int]]] = [
        (r, float) for r in d.get("floating_point_range") or []]
    ranges += [(r, int) for r in d.get("integer_range") or []]
    if ranges:
        first, kind = ranges[0]
        lines.append(f"    Min value: {kind(first.get('from_value', 0))}")
        lines.append(f"    Max value: {kind(first.get('to_value', 0))}")
        if first.get("step"):
            lines.append(f"    Step: {kind(first['step'])}")
    if d.get("additional_constraints"):
        lines.append(f"    Additional constraints: {d['additional_constraints']}")
    return lines


async def cmd_param_describe(args: argparse.Namespace, out: Out) -> int:
    """``param describe NODE NAME...``: type, description and constraints of each."""
    async def body(s: CliSession) -> int:
        node = await s.node(args.node_name, args.wait)
        reply = await _call(s, node, "describe_parameters", {"names": args.parameter_names})
        descriptors = list(reply.get("descriptors", []))
        if not descriptors and args.parameter_names:
            raise CliError(EXIT_NOT_FOUND, f"{node} has not declared "
                                           f"{', '.join(args.parameter_names)}")
        for d in descriptors:
            for line in _describe_lines(d):
                out.line(line)
        return EXIT_OK
    return await with_session(args, body)


async def cmd_param_dump(args: argparse.Namespace, out: Out) -> int:
    """``param dump NODE``: every parameter in ros2's parameter-file YAML."""
    _need_yaml("dump")

    async def body(s: CliSession) -> int:
        node = await s.node(args.node_name, args.wait)
        names = await _names(s, node)
        values = await _get(s, node, names) if names else []
        if len(values) != len(names):
            raise CliError(EXIT_REMOTE, f"{node}/get_parameters answered {len(values)} values "
                                        f"for {len(names)} parameters (one left meanwhile?)")
        out.line(dump_yaml(node, {n: to_python(v) for n, v in zip(names, values, strict=True)}))
        return EXIT_OK
    return await with_session(args, body)


async def cmd_param_load(args: argparse.Namespace, out: Out) -> int:
    """``param load NODE FILE``: set every parameter of a ``param dump`` file (all its node
    entries, ``/**`` first unless ``--no-use-wildcard``), one result line each."""
    _need_yaml("load")
    path = Path(args.parameter_file)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CliError(EXIT_USAGE, f"cannot read the parameter file {path}: "
                                   f"{getattr(exc, 'strerror', None) or exc}") from None
    try:
        params = parameters_from_yaml(text, str(path), not args.no_use_wildcard)
    except ArgumentError as exc:
        raise CliError(EXIT_USAGE, str(exc)) from None

    async def body(s: CliSession) -> int:
        node = await s.node(args.node_name, args.wait)
        results = await _set(s, node, params)
        if len(results) != len(params):
            raise CliError(EXIT_REMOTE, f"{node}/set_parameters answered {len(results)} "
                                        f"results for {len(params)} parameters")
        code = EXIT_OK
        for (name, _), result in zip(params, results, strict=True):
            good, line = _result_line(result, f"Set parameter {name} successful",
                                      f"Set parameter {name} failed")
            if good:
                out.line(line)
            else:
                print(line, file=sys.stderr, flush=True)
                code = EXIT_REMOTE
        return code
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``param`` and its commands."""
    nwait = node_wait_parser()
    sub = kit.group(groups, "param", "parameters: list, get, set, describe, dump, load, delete",
                    "list,get,set,describe,dump,load,delete")
    p = kit.leaf(sub, "list", cmd_param_list, "list the parameters of a node, or of every node",
                 nwait)
    p.add_argument("node_name", nargs="?", help="the node (default: every node)")
    p.add_argument("--include-hidden-nodes", action="store_true",
                   help="every node's: hidden nodes too (a part of the name starts with _)")
    p.add_argument("--filter", help="only the names this regular expression matches")
    p.add_argument("--param-prefixes", nargs="+", default=[], metavar="PREFIX",
                   help="only the parameters with these prefixes")
    p.add_argument("--param-type", action="store_true", help="print each parameter's type")
    p = kit.leaf(sub, "get", cmd_param_get, "print a parameter's value", nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("parameter_name", help="the parameter")
    p.add_argument("--hide-type", action="store_true", help="print the value alone")
    p = kit.leaf(sub, "set", cmd_param_set, "set a parameter", nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("parameter_name", help="the parameter")
    p.add_argument("value", help="the value in YAML: 5 (integer), 5.0 (double), true, "
                                 "hello, '[1, 2]' (integer array)")
    p = kit.leaf(sub, "describe", cmd_param_describe,
                 "a parameter's type, description and constraints", nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("parameter_names", nargs="+", help="the parameters")
    p = kit.leaf(sub, "dump", cmd_param_dump,
                 "print every parameter of a node as a ros2 parameter file (YAML)", nwait)
    p.add_argument("node_name", help="the node")
    p = kit.leaf(sub, "load", cmd_param_load, "set the parameters of a ros2 parameter file",
                 nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("parameter_file", help="the file, as 'param dump' or ros2 param dump wrote it")
    p.add_argument("--no-use-wildcard", action="store_true",
                   help="do not load the file's '/**' entry into the node")
    p = kit.leaf(sub, "delete", cmd_param_delete, "delete (undeclare) a parameter", nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("parameter_name", help="the parameter")
