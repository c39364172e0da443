"""``roslibpy-lite service list|type|find|call``."""

from __future__ import annotations

import argparse
import json
from typing import Any

from msgs.runtime import Service

from ..exceptions import (
    ServiceError,
)
from .common import (
    EXIT_NOT_FOUND,
    EXIT_OK,
    EXIT_REMOTE,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    check_values,
    cli_values,
    find_by_type,
    local_class,
    print_listing,
    type_parts,
    with_session,
)
from .format import to_yaml


async def cmd_service_list(args: argparse.Namespace, out: Out) -> int:
    """``service list [-t]``."""
    async def body(s: CliSession) -> int:
        if args.show_types or args.json:
            found = await s.ros.graph.services(timeout=s.timeout)
            return print_listing(out, args, [(x.name, x.type) for x in found])
        names = sorted((await s.rosapi("services")).get("services", []))
        return print_listing(out, args, [(n, "") for n in names])
    return await with_session(args, body)


async def cmd_service_type(args: argparse.Namespace, out: Out) -> int:
    """``service type SERVICE``."""
    async def body(s: CliSession) -> int:
        await s.service_server(args.service, args.wait)
        found = str((await s.rosapi("service_type", {"service": args.service})).get("type", ""))
        if not found:
            raise CliError(EXIT_NOT_FOUND, f"unknown service {args.service}")
        out.line(found)
        return EXIT_OK
    return await with_session(args, body)


async def cmd_service_find(args: argparse.Namespace, out: Out) -> int:
    """``service find TYPE [-c]``: the services of that type."""
    return await find_by_type(args, out, "service", args.service_type)


async def cmd_service_call(args: argparse.Namespace, out: Out) -> int:
    """``service call SERVICE TYPE [VALUES]``: print the response."""
    type_parts(args.type, "srv")
    srv = local_class(args.type, "srv")
    request_cls = srv.Request if isinstance(srv, type) and issubclass(srv, Service) else None
    values = check_values(cli_values(args.values, "VALUES"), request_cls, "VALUES")
    if args.call_timeout is not None and args.call_timeout <= 0:
        raise CliError(EXIT_USAGE, f"--call-timeout must be > 0, got {args.call_timeout}")

    async def body(s: CliSession) -> int:
        await s.service_server(args.service, args.wait)
        try:
            response = await s.ros.call_service(args.service, args.type, values,
                                                timeout=args.call_timeout)
        except ServiceError as exc:
            raise CliError(EXIT_REMOTE, str(exc)) from None
        if args.json:
            out.line(json.dumps(response, separators=(",", ":")))
        else:
            out.line(to_yaml(response))
        return EXIT_OK
    return await with_session(args, body)


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``service`` and its commands."""
    ssub = kit.group(groups, "service", "services: list, type, find, call", "list,type,find,call")
    kit.listing(ssub, cmd_service_list, "list the services", "service", hidden=True)
    p = kit.leaf(ssub, "type", cmd_service_type, "print a service's type", kit.swait)
    p.add_argument("service")
    kit.finding(ssub, cmd_service_find, "service", "rcl_interfaces/srv/ListParameters")
    p = kit.leaf(ssub, "call", cmd_service_call, "call a service and print the response", kit.fmt,
             kit.swait)
    p.add_argument("service")
    p.add_argument("type", help="service type, e.g. mult_msgs/srv/MultFloats")
    p.add_argument("values", nargs="?", default=None,
                   help="the request in YAML or JSON, e.g. \"{x: 2.5, y: 4.0}\" (default: {})")
    p.add_argument("--call-timeout", type=float, default=10.0,
                   help="seconds to wait for the response (default 10)")
