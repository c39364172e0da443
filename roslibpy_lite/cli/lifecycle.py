"""``roslibpy-lite lifecycle nodes|get|list|set``, as ``ros2 lifecycle`` does them.

A lifecycle (managed) node serves ``lifecycle_msgs`` services under its name:
``/node/get_state``, ``/node/change_state``, ``/node/get_available_transitions`` and
``/node/get_transition_graph``; these commands call them through the bridge. A lifecycle
node is one serving ``/node/get_state`` of type ``lifecycle_msgs/srv/GetState``, as in
ros2. Output is ``ros2 lifecycle``'s: ``unconfigured [1]``, ``- configure [1]`` with
its ``Start:``/``Goal:`` lines, ``Transitioning successful``.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from typing import Any

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

GET_STATE = "lifecycle_msgs/srv/GetState"
"""The type of a lifecycle node's ``get_state`` service: what makes it one."""

_TYPES = {
    "get_state": GET_STATE,
    "change_state": "lifecycle_msgs/srv/ChangeState",
    "get_available_transitions": "lifecycle_msgs/srv/GetAvailableTransitions",
    "get_transition_graph": "lifecycle_msgs/srv/GetAvailableTransitions",
}
"""A lifecycle node's services (``/node/<name>``) this module calls, and their types."""


async def lifecycle_nodes(s: CliSession, include_hidden: bool = False) -> list[str]:
    """The lifecycle nodes in the graph, sorted: nodes serving ``<node>/get_state`` as a
    ``lifecycle_msgs/srv/GetState``."""
    services = (await s.rosapi("services_for_type", {"type": GET_STATE})).get("services", [])
    serving = {str(n)[: -len("/get_state")] for n in services if str(n).endswith("/get_state")}
    nodes = await s.ros.graph.node_names(timeout=s.timeout)
    return sorted(n for n in nodes if n in serving and (include_hidden or not hidden(n)))


async def _lifecycle_node(s: CliSession, name: str, wait: float) -> str:
    """``name``, fully qualified, once it is a lifecycle node in the graph."""
    node = await s.node(name, wait)
    if node not in await lifecycle_nodes(s, include_hidden=True):
        raise CliError(EXIT_NOT_FOUND, f"{node} is not a lifecycle node (it serves no "
                                       f"{node}/get_state of type {GET_STATE})")
    return node


async def _call(s: CliSession, node: str, service: str, request: dict[str, Any] | None = None
                ) -> dict[str, Any]:
    return await s.node_call(node, service, _TYPES[service], request)


def _state(reply: dict[str, Any]) -> str:
    state = reply.get("current_state", {})
    return f"{state.get('label', '')} [{state.get('id', '')}]"


async def cmd_lifecycle_nodes(args: argparse.Namespace, out: Out) -> int:
    """``lifecycle nodes [-a] [-c]``: the lifecycle nodes, one a line (``-c``: how many)."""
    async def body(s: CliSession) -> int:
        nodes = await lifecycle_nodes(s, args.all)
        if args.count_nodes:
            out.line(str(len(nodes)))
        for node in () if args.count_nodes else nodes:
            out.line(node)
        return EXIT_OK
    return await with_session(args, body)


async def cmd_lifecycle_get(args: argparse.Namespace, out: Out) -> int:
    """``lifecycle get [NODE]``: ``label [id]`` of the node's state; of every lifecycle
    node (``/node: label [id]``) without NODE."""
    async def body(s: CliSession) -> int:
        if args.node_name:
            node = await _lifecycle_node(s, args.node_name, args.wait)
            out.line(_state(await _call(s, node, "get_state")))
            return EXIT_OK
        nodes = await lifecycle_nodes(s, args.include_hidden_nodes)
        replies = await asyncio.gather(*(_call(s, n, "get_state") for n in nodes),
                                       return_exceptions=True)
        code = EXIT_OK
        for node, reply in zip(nodes, replies, strict=True):
            if isinstance(reply, BaseException):
                if not isinstance(reply, Exception):
                    raise reply
                print(f"Exception while calling service of node '{node}': {reply}",
                      file=sys.stderr, flush=True)
                code = EXIT_REMOTE
                continue
            out.line(f"{node}: {_state(reply)}")
        return code
    return await with_session(args, body)


def _transitions(reply: dict[str, Any]) -> list[dict[str, Any]]:
    return list(reply.get("available_transitions", []))


def _transition_lines(t: dict[str, Any]) -> list[str]:
    """``ros2 lifecycle list``'s three lines for one TransitionDescription."""
    tr, start, goal = t.get("transition", {}), t.get("start_state", {}), t.get("goal_state", {})
    return [f"- {tr.get('label', '')} [{tr.get('id', '')}]",
            f"\tStart: {start.get('label', '')}", f"\tGoal: {goal.get('label', '')}"]


async def cmd_lifecycle_list(args: argparse.Namespace, out: Out) -> int:
    """``lifecycle list NODE [-a]``: the transitions available now (``-a``: every one)."""
    async def body(s: CliSession) -> int:
        node = await _lifecycle_node(s, args.node_name, args.wait)
        service = "get_transition_graph" if args.all else "get_available_transitions"
        for t in _transitions(await _call(s, node, service)):
            for line in _transition_lines(t):
                out.line(line)
        return EXIT_OK
    return await with_session(args, body)


async def cmd_lifecycle_set(args: argparse.Namespace, out: Out) -> int:
    """``lifecycle set NODE TRANSITION``: trigger the transition named (or numbered)."""
    async def body(s: CliSession) -> int:
        node = await _lifecycle_node(s, args.node_name, args.wait)
        available = [t.get("transition", {})
                     for t in _transitions(await _call(s, node, "get_available_transitions"))]
        chosen = next((t for t in available if t.get("label") == args.transition), None)
        if chosen is None:
            chosen = next((t for t in available if str(t.get("id")) == args.transition), None)
        if chosen is None:
            listed = ", ".join(f"{t.get('label')} [{t.get('id')}]" for t in available)
            raise CliError(EXIT_USAGE, f"Unknown transition requested, available ones are: "
                                       f"{listed or 'none'}")
        transition = {"id": int(chosen.get("id", 0)), "label": str(chosen.get("label", ""))}
        reply = await _call(s, node, "change_state", {"transition": transition})
        if reply.get("success"):
            out.line("Transitioning successful")
            return EXIT_OK
        print("Transitioning failed", file=sys.stderr, flush=True)
        return EXIT_REMOTE
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``lifecycle`` and its commands."""
    nwait = node_wait_parser()
    sub = kit.group(groups, "lifecycle", "lifecycle (managed) nodes: nodes, get, list, set",
                    "nodes,get,list,set")
    p = kit.leaf(sub, "nodes", cmd_lifecycle_nodes, "list the lifecycle nodes")
    p.add_argument("-a", "--all", action="store_true", help="hidden nodes too")
    p.add_argument("-c", "--count-nodes", action="store_true",
                   help="print only how many there are")
    p = kit.leaf(sub, "get", cmd_lifecycle_get, "print a lifecycle node's state", nwait)
    p.add_argument("node_name", nargs="?", help="the node (default: every lifecycle node)")
    p.add_argument("--include-hidden-nodes", action="store_true",
                   help="every node's: hidden nodes too")
    p = kit.leaf(sub, "list", cmd_lifecycle_list, "list the transitions a node can take now",
                 nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("-a", "--all", action="store_true",
                   help="every transition of the state machine, not only those from now")
    p = kit.leaf(sub, "set", cmd_lifecycle_set, "trigger a lifecycle transition", nwait)
    p.add_argument("node_name", help="the node")
    p.add_argument("transition", help="the transition's label (configure, activate, ...) or id")
