"""``roslibpy-lite``: a ``ros2``-like command-line tool that needs no ROS, only a rosbridge.

Examples::

    roslibpy-lite topic list -t
    roslibpy-lite topic echo /example_counter --count 3
    roslibpy-lite topic pub /chatter std_msgs/msg/String "{data: hello}" --once
    roslibpy-lite topic hz /imu --duration 5
    roslibpy-lite service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"
    roslibpy-lite action send_goal /integrate_imu mult_msgs/action/IntegrateImu "{seconds: 2}" -f
    roslibpy-lite node list
    roslibpy-lite interface show sensor_msgs/msg/Imu
    roslibpy-lite param get /controller speed_limit
    roslibpy-lite param dump /controller
    roslibpy-lite lifecycle set /map_server activate
    roslibpy-lite topic bw /camera

The bridge is ``--url`` (default ``$ROSLIBPY_LITE_URL``, else
``ws://127.0.0.1:9090``); a bridge that requires a token gets ``--token``
(``$ROSLIBPY_LITE_TOKEN``), a ``wss://`` bridge with a private CA ``--cafile``
(``$ROSLIBPY_LITE_CAFILE``). Introspection goes through the bridge's
``/rosapi/*`` services. Errors print one line on stderr and exit with a
distinct status (see :data:`EXIT_CODES`).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import sys
from collections.abc import Sequence
from typing import TextIO

from ..exceptions import (
    ConnectError,
    ConnectionClosed,
    RemoteError,
    RosTimeoutError,
    UsageError,
)
from . import action, bag, interface, lifecycle, mcp, node, param, service, topic, topic_stats
from .common import (
    DEFAULT_URL,
    EXIT_CODES,
    EXIT_CONNECT,
    EXIT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_NOT_FOUND,
    EXIT_OK,
    EXIT_REMOTE,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    CliError,
    Command,
    Kit,
    Out,
    Parser,
)
from .format import have_yaml

__all__ = [
    "DEFAULT_URL",
    "EXAMPLES",
    "EXIT_CODES",
    "EXIT_CONNECT",
    "EXIT_ERROR",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_FOUND",
    "EXIT_OK",
    "EXIT_REMOTE",
    "EXIT_TIMEOUT",
    "EXIT_USAGE",
    "CliError",
    "build_parser",
    "main",
]


EXAMPLES: tuple[str, ...] = (
    "topic list -t",
    "topic echo /example_counter --count 3",
    'topic pub /chatter std_msgs/msg/String "{data: hello}" --once',
    "topic hz /imu --duration 3",
    'service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"',
    'action send_goal /integrate_imu mult_msgs/action/IntegrateImu "{seconds: 0.5}" --feedback',
    "node list",
    "interface show sensor_msgs/msg/Imu",
)
"""The examples ``--help`` shows (tests/cli/test_examples.py runs each against the demo's parts)."""


def _epilog() -> str:
    codes = "\n".join(f"  {code:<4} {text}" for code, text in EXIT_CODES.items())
    yaml_note = ("VALUES are YAML or JSON" if have_yaml()
                 else "VALUES are JSON (for YAML: pip install pyyaml, or the wheel's [cli] "
                 "extra)")
    examples = "\n".join(f"  roslibpy-lite {e}" for e in EXAMPLES)
    return f"examples:\n{examples}\n\n{yaml_note}.\n\nexit status:\n{codes}"


class _RootParser(Parser):
    """Fills ``--url``/``--timeout`` defaults after parsing, so the options may stand
    before or after the subcommand (argparse would let a subcommand's defaults
    overwrite a value given before it)."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, rest = super().parse_known_args(args, namespace)
        if getattr(parsed, "url", None) is None:
            parsed.url = os.environ.get("ROSLIBPY_LITE_URL") or DEFAULT_URL
        if getattr(parsed, "timeout", None) is None:
            parsed.timeout = 5.0
        if getattr(parsed, "token", None) is None:
            parsed.token = os.environ.get("ROSLIBPY_LITE_TOKEN") or None
        if getattr(parsed, "cafile", None) is None:
            parsed.cafile = os.environ.get("ROSLIBPY_LITE_CAFILE") or None
        return parsed, rest


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and documentation)."""
    common = Parser(add_help=False)
    common.add_argument("--url", default=argparse.SUPPRESS,
                        help="the bridge (default $ROSLIBPY_LITE_URL or " + DEFAULT_URL + ")")
    common.add_argument("--timeout", type=float, default=argparse.SUPPRESS,
                        help="seconds to wait for the bridge: connecting and each "
                             "introspection call (default 5)")
    common.add_argument("--token", default=argparse.SUPPRESS,
                        help="token for a bridge that requires one (default "
                             "$ROSLIBPY_LITE_TOKEN); sent as an Authorization header")
    common.add_argument("--cafile", default=argparse.SUPPRESS,
                        help="CA file (PEM) that signed a wss:// bridge's certificate "
                             "(default $ROSLIBPY_LITE_CAFILE, else the system's CAs)")
    fmt = Parser(add_help=False)
    fmt.add_argument("--json", action="store_true", help="JSON output (one object per line)")
    wait = Parser(add_help=False)
    wait.add_argument("--wait", type=float, default=2.0, metavar="SEC",
                      help="seconds to wait for an unknown topic to appear in the ROS graph "
                           "(default 2)")
    swait = Parser(add_help=False)
    swait.add_argument("--wait", type=float, default=2.0, metavar="SEC",
                       help="seconds to wait for the service to appear in the ROS graph "
                            "(default 2)")

    root = _RootParser(
        prog="roslibpy-lite",
        description="Talk to a ROS 2 robot through a rosbridge server; no ROS needed here.",
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    groups = root.add_subparsers(dest="group",
                                 metavar="{topic,service,param,lifecycle,node,interface,action,"
                                         "bag,mcp}",
                                 parser_class=Parser)
    groups.required = True

    kit = Kit(common, fmt, wait, swait)
    for noun in (topic, service, param, lifecycle, node, interface, action, bag, mcp):
        noun.add_parsers(groups, kit)
    return root


_client_log = logging.getLogger("roslibpy_lite")

_STREAMING = {topic.cmd_topic_echo, topic.cmd_topic_hz, topic.cmd_topic_pub,
              topic_stats.cmd_topic_bw, topic_stats.cmd_topic_delay,
              bag.cmd_bag_record, bag.cmd_bag_play, mcp.cmd_mcp}


def _fail(code: int, message: str) -> int:
    print(f"roslibpy-lite: {message}", file=sys.stderr, flush=True)
    return code


def main(argv: Sequence[str] | None = None, *, stdout: TextIO | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    try:
        args = build_parser().parse_args(argv)
    except CliError as exc:
        return _fail(exc.code, exc.message)
    except SystemExit as exc:  # --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    if args.timeout <= 0:
        return _fail(EXIT_USAGE, f"--timeout must be > 0, got {args.timeout}")
    out = Out(stdout)
    func: Command = args.func
    if not _client_log.handlers:  # errors are reported here, once; no stray log lines
        _client_log.addHandler(logging.NullHandler())
    try:
        return asyncio.run(func(args, out))
    except KeyboardInterrupt:
        return EXIT_OK if func in _STREAMING else EXIT_INTERRUPTED
    except CliError as exc:
        return _fail(exc.code, exc.message)
    except RosTimeoutError as exc:
        return _fail(EXIT_TIMEOUT, str(exc))
    except ConnectError as exc:
        return _fail(EXIT_CONNECT, str(exc))
    except ConnectionClosed as exc:
        return _fail(EXIT_CONNECT, f"connection lost: {exc}")
    except RemoteError as exc:
        # A type the bridge does not know is the same mistake as one the client does not
        # know (a typo in TYPE): one exit code for both, whoever noticed it.
        code = EXIT_USAGE if ": unknown type '" in str(exc) else EXIT_REMOTE
        return _fail(code, str(exc))
    except UsageError as exc:
        return _fail(EXIT_USAGE, str(exc))
    except BrokenPipeError:
        # The reader went away (``| head``): stop quietly, as other tools do.
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - keep interpreter exit quiet
        return EXIT_OK
    except Exception as exc:
        return _fail(EXIT_ERROR, f"unexpected error: {type(exc).__name__}: {exc}")


if __name__ == "__main__":
    sys.exit(main())
