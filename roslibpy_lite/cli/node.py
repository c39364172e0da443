"""``roslibpy-lite node list|info``."""

from __future__ import annotations

import argparse
import json
from typing import Any

from rosbridge_core.protocol.names import absolute_name

from .common import (
    EXIT_NOT_FOUND,
    EXIT_OK,
    CliError,
    CliSession,
    Kit,
    Out,
    with_session,
)


async def cmd_node_list(args: argparse.Namespace, out: Out) -> int:
    """``node list``."""
    async def body(s: CliSession) -> int:
        names = await s.ros.graph.node_names(timeout=s.timeout)
        if args.json:
            out.line(json.dumps(names))
        for name in names if not args.json else ():
            out.line(name)
        return EXIT_OK
    return await with_session(args, body)


async def cmd_node_info(args: argparse.Namespace, out: Out) -> int:
    """``node info NODE``: what a node publishes, subscribes to and serves."""
    async def body(s: CliSession) -> int:
        name = absolute_name(args.node)
        if name not in await s.ros.graph.node_names(timeout=s.timeout):
            raise CliError(EXIT_NOT_FOUND, f"unknown node {name}")
        node = await s.ros.graph.node(name, timeout=s.timeout)
        lists = {"subscribing": node.subscribers, "publishing": node.publishers,
                 "services": node.services}
        if args.json:
            out.line(json.dumps({"name": name, **{k: list(v) for k, v in lists.items()}}))
            return EXIT_OK
        out.line(name)
        for title, key in (("Subscribers", "subscribing"), ("Publishers", "publishing"),
                           ("Service Servers", "services")):
            out.line(f"  {title}:")
            for item in lists[key]:
                out.line(f"    {item}")
        return EXIT_OK
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``node`` and its commands."""
    nsub = kit.group(groups, "node", "nodes: list, info", "list,info")
    kit.leaf(nsub, "list", cmd_node_list, "list the nodes", kit.fmt)
    p = kit.leaf(nsub, "info", cmd_node_info, "what a node publishes, subscribes to and serves",
                 kit.fmt)
    p.add_argument("node")
