"""``roslibpy-lite action list|info|type|send_goal``, in the habits of ``ros2 action``.

``send_goal ACTION TYPE [VALUES] [--feedback]`` prints what ``ros2 action
send_goal`` prints (the goal, each feedback with ``--feedback``, the result
and its status); Ctrl+C cancels the goal, waits (``--cancel-wait`` s) for its
end and exits with 130. A goal that does not succeed exits with 6
(EXIT_REMOTE), an action nobody serves with 4 (EXIT_NOT_FOUND).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import sys
from typing import Any

from msgs.runtime import Action

from ..actions import ActionError, GoalHandle, GoalStatus
from .common import (
    EXIT_INTERRUPTED,
    EXIT_NOT_FOUND,
    EXIT_OK,
    EXIT_REMOTE,
    EXIT_USAGE,
    CliError,
    CliSession,
    Kit,
    Out,
    Parser,
    check_values,
    cli_values,
    for_display,
    local_class,
    print_line,
    print_listing,
    type_parts,
    with_session,
)
from .format import to_yaml


async def cmd_action_list(args: argparse.Namespace, out: Out) -> int:
    """``action list [-t]``."""
    async def body(s: CliSession) -> int:
        if args.show_types or args.json:
            found = await s.ros.graph.actions(timeout=s.timeout)
            return print_listing(out, args, [(x.name, x.type) for x in found])
        names = sorted((await s.rosapi("action_servers")).get("action_servers", []))
        return print_listing(out, args, [(n, "") for n in names])
    return await with_session(args, body)


async def cmd_action_type(args: argparse.Namespace, out: Out) -> int:
    """``action type ACTION``."""
    return await print_line(args, out, lambda s: s.action_type(args.action, args.wait))


async def cmd_action_info(args: argparse.Namespace, out: Out) -> int:
    """``action info ACTION``: its type and the nodes serving it."""
    async def body(s: CliSession) -> int:
        type_ = await s.action_type(args.action, args.wait)
        goal_service = args.action.rstrip("/") + "/_action/send_goal"
        servers = [n.name for n in await s.ros.graph.nodes(timeout=s.timeout)
                   if goal_service in n.services]
        if args.json:
            out.line(json.dumps({"name": args.action, "type": type_,
                                 "action_servers": servers}))
            return EXIT_OK
        out.line(f"Action: {args.action}")
        out.line(f"Type: {type_}")
        out.line(f"Action servers: {len(servers)}")
        for node in servers:
            out.line(f"    {node}")
        return EXIT_OK
    return await with_session(args, body)


async def cmd_action_send_goal(args: argparse.Namespace, out: Out) -> int:
    """``action send_goal ACTION TYPE [VALUES]``: send a goal and print its result."""
    type_parts(args.type, "action")
    cls = local_class(args.type, "action")
    action_cls = cls if isinstance(cls, type) and issubclass(cls, Action) else None
    goal_values = check_values(cli_values(args.values, "VALUES"),
                               action_cls.Goal if action_cls else None, "VALUES")
    shown = action_cls if not args.json else None  # NaN and uint8[] shown as ros2 does
    if args.cancel_wait <= 0:
        raise CliError(EXIT_USAGE, f"--cancel-wait must be > 0, got {args.cancel_wait}")

    async def body(s: CliSession) -> int:
        await s.action_type(args.action, args.wait)
        if not args.json:
            out.line("Sending goal:")
            out.line(_indent(to_yaml(goal_values)))
        goal = await s.ros.send_goal(args.action, args.type, goal_values,
                                     feedback=args.feedback)
        try:
            return await _follow(goal, args, out, shown)
        except asyncio.CancelledError:  # Ctrl+C: cancel the goal, then exit
            task = asyncio.current_task()
            if task is None or task.uncancel() > 0:
                raise
            return await _cancel(goal, args, out)
    return await with_session(args, body)


async def _follow(goal: GoalHandle, args: argparse.Namespace, out: Out,
                  shown: type[Action] | None) -> int:
    try:
        await goal.accepted()  # our bridge says so at once; a stock one by feedback or result
    except ActionError as exc:
        raise _goal_error(exc) from None
    if not args.json:
        out.line(f"Goal accepted with ID: {goal.id}")
        out.line("")
    async for fb in goal:
        if args.json:
            out.line(json.dumps({"feedback": fb}, separators=(",", ":")))
        else:
            out.line("Feedback:")
            out.line(_indent(to_yaml(for_display(fb, shown.Feedback if shown else None))))
    try:
        outcome = await goal.result()
    except ActionError as exc:
        raise _goal_error(exc) from None
    if args.json:
        out.line(json.dumps({"status": outcome.status.name, "result": outcome.values},
                            separators=(",", ":")))
    else:
        out.line("Result:")
        values = outcome.values if outcome.values is not None else {}
        out.line(_indent(to_yaml(for_display(values, shown.Result if shown else None))))
        out.line("")
        out.line(f"Goal finished with status: {outcome.status.name}")
    if outcome.succeeded:
        return EXIT_OK
    print(f"roslibpy-lite: goal to {args.action} ended {outcome.status.name}",
          file=sys.stderr, flush=True)
    return EXIT_REMOTE


def _goal_error(exc: ActionError) -> CliError:
    code = EXIT_NOT_FOUND if "does not exist" in exc.reason else EXIT_REMOTE
    return CliError(code, str(exc))


async def _cancel(goal: GoalHandle, args: argparse.Namespace, out: Out) -> int:
    print("Canceling goal...", file=sys.stderr, flush=True)
    status = goal.status
    with contextlib.suppress(Exception):
        await goal.cancel()
        status = (await goal.result(timeout=args.cancel_wait)).status
    if status is GoalStatus.CANCELED:
        print("Goal canceled.", file=sys.stderr, flush=True)
    else:
        print(f"roslibpy-lite: interrupted; the goal's status is {status.name}",
              file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED


def _indent(text: str) -> str:
    return "\n".join("  " + line if line else line for line in text.rstrip("\n").split("\n"))


def add_parsers(groups: Any, kit: Kit) -> None:
    """Add ``action`` and its commands."""
    awaits = Parser(add_help=False)
    awaits.add_argument("--wait", type=float, default=2.0, metavar="SEC",
                        help="seconds to wait for the action to appear in the ROS graph "
                             "(default 2)")
    asub = kit.group(groups, "action", "actions: list, info, type, send_goal",
                     "list,info,type,send_goal")
    kit.listing(asub, cmd_action_list, "list the action servers", "action")
    p = kit.leaf(asub, "info", cmd_action_info, "an action's type and the nodes serving it",
                 kit.fmt, awaits)
    p.add_argument("action")
    p = kit.leaf(asub, "type", cmd_action_type, "print an action's type", awaits)
    p.add_argument("action")
    p = kit.leaf(asub, "send_goal", cmd_action_send_goal,
                 "send a goal and print its result (Ctrl+C cancels the goal)", kit.fmt, awaits)
    p.add_argument("action")
    p.add_argument("type", help="action type, e.g. mult_msgs/action/IntegrateImu")
    p.add_argument("values", nargs="?", default=None,
                   help="the goal in YAML or JSON, e.g. \"{seconds: 2.0}\" (default: {})")
    p.add_argument("-f", "--feedback", action="store_true", help="print the feedback")
    p.add_argument("--cancel-wait", type=float, default=5.0, metavar="SEC",
                   help="after Ctrl+C, seconds to wait for the canceled goal's end (default 5)")
