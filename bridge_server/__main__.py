"""``python -m bridge_server``: run the rosbridge-protocol server.

It logs ``bridge_server listening on ws://HOST:PORT`` to stderr once it is
ready, one line per client connection and disconnection, and exits with
status 0 within about a second of SIGINT or SIGTERM. A start it refuses exits 1 (2 for an
exposed port without --auth-file or --insecure, or a bad --robot); whatever rclpy's threads
do as the process ends, that status is the process's (:mod:`bridge_server._exit`).

DDS discovery is kept on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``)
unless the environment already sets the variable.

Subcommands, each with its own ``--help``: ``add-principal`` and ``remove-principal``
(an auth file's principals) and ``healthcheck`` (exit 0 once the running bridge is ready).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import faulthandler
import logging
import os
import signal
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

from bridge_server._exit import ends_process
from bridge_server.allocator import tune_allocator

try:
    from bridge_server import eventloop
    from bridge_server.front.handshake import Security
    from bridge_server.front.server import WRITE_LIMIT
    from bridge_server.zenoh import link as zenoh_link
    from bridge_server.zenoh import robot_link
    from bridge_server.zenoh.keys import check_robot
    from bridge_server.zenoh.priority import parse_overrides
    from bridge_server.zenoh.replay import (
        DEFAULT_REPLAY_BYTES,
        DEFAULT_REPLAY_COUNT,
        DEFAULT_REPLAY_TOTAL_BYTES,
        ReplayWindow,
    )
    from rosbridge_core import security
    from rosbridge_core.codec import budget as decode_budget
    from rosbridge_core.interfaces import BridgeError
    from rosbridge_core.protocol import keepalive
    from rosbridge_core.protocol.constants import DEFAULT_PORT
    from rosbridge_core.security.options import MAX_MESSAGE_SIZE
    from rosbridge_core.session.resume import ResumeConfig
    from rosbridge_core.session.session import DEFAULT_QUEUE_LENGTH, SessionConfig
except ModuleNotFoundError as _missing:  # a client-only install: say which extra to add
    from bridge_server._requires import missing_dependency

    missing_dependency(_missing)

if TYPE_CHECKING:
    from bridge_server.front.server import Bridge
    from rosbridge_core.security.permissions import Role

__all__ = ["main", "parse_args"]

log = logging.getLogger("bridge_server")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="roslibpy-lite-bridge",
        description="A rosbridge v2 protocol server on rclpy (ROS 2 Jazzy).",
        epilog="subcommands (each with its own --help): add-principal and remove-principal "
        "(an auth file's principals), healthcheck (exit 0 once the running bridge is ready)",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"port (default {DEFAULT_PORT}; 0: any free port)")
    p.add_argument(
        "--max-message-size",
        type=int,
        default=MAX_MESSAGE_SIZE,
        help=f"largest inbound frame in bytes (default {MAX_MESSAGE_SIZE // 2**20} MiB; raise it "
        "for large point clouds or maps)",
    )
    p.add_argument(
        "--keepalive-interval",
        type=float,
        default=keepalive.DEFAULT_INTERVAL,
        help="seconds a client may be silent before the bridge pings it "
        f"(default {keepalive.DEFAULT_INTERVAL:g}; 0: off)",
    )
    p.add_argument(
        "--keepalive-timeout",
        type=float,
        default=keepalive.DEFAULT_TIMEOUT,
        help="further seconds without any sign of a pinged client before its link counts as "
        f"dead and everything it owned is dropped (default {keepalive.DEFAULT_TIMEOUT:g})",
    )
    p.add_argument(
        "--session-keep",
        type=float,
        default=ResumeConfig.session_keep,
        help="seconds the session of a client whose link dropped is kept for it to resume "
        "(subscriptions with their queues, services, actions, unconfirmed frames; our client "
        f"asks for this, stock clients never do; default {ResumeConfig.session_keep:g}; 0: off)",
    )
    p.add_argument(
        "--sessions-per-principal",
        type=int,
        default=ResumeConfig.sessions_per_principal,
        help="most kept sessions per principal (or of unauthenticated clients); the oldest "
        f"goes first (default {ResumeConfig.sessions_per_principal})",
    )
    p.add_argument(
        "--resume-frames",
        type=int,
        default=ResumeConfig.resume_frames,
        help="most frames a session keeps until its client confirms them, to send again after "
        f"a resume (default {ResumeConfig.resume_frames})",
    )
    p.add_argument(
        "--resume-bytes",
        type=int,
        default=ResumeConfig.resume_bytes,
        help=f"most bytes of such frames per session (default {ResumeConfig.resume_bytes // 2**20} "
        "MiB)",
    )
    p.add_argument(
        "--node-name",
        default=None,
        help="the bridge's ROS node name (default roslibpy_lite_bridge_<process id>, so that "
        "several bridges on one ROS domain never share one)",
    )
    p.add_argument(
        "--send-queue",
        type=int,
        default=DEFAULT_QUEUE_LENGTH,
        help="messages kept per subscription for a slow client when it asks for "
        f"queue_length 0 (default {DEFAULT_QUEUE_LENGTH}); the oldest are dropped",
    )
    p.add_argument(
        "--write-limit",
        type=int,
        default=WRITE_LIMIT,
        help=f"socket write buffer high-water mark per client in bytes (default {WRITE_LIMIT})",
    )
    p.add_argument(
        "--publisher-grace",
        type=float,
        default=2.0,
        help="seconds a disconnected client's publishers live on (default 2)",
    )
    p.add_argument(
        "--call-timeout",
        type=float,
        default=SessionConfig.call_timeout,
        help=f"default call_service timeout in seconds (default {SessionConfig.call_timeout:g})",
    )
    p.add_argument(
        "--served-call-timeout",
        type=float,
        default=SessionConfig.served_call_timeout,
        help="seconds a ROS caller waits for a client-served service "
        f"(default {SessionConfig.served_call_timeout:g})",
    )
    p.add_argument(
        "--goal-timeout",
        type=float,
        default=SessionConfig.goal_timeout,
        help="seconds an action goal may run through the bridge before it is canceled "
        "(goals clients send) or aborted (goals clients serve); default 0: no limit",
    )
    p.add_argument(
        "--compression",
        choices=("none", "deflate"),
        default="none",
        help="websocket permessage-deflate (default none: it costs CPU)",
    )
    p.add_argument(
        "--metrics-port",
        type=int,
        default=None,
        help="also answer /metrics (and /healthz, /readyz, the status page) on this port; "
        "they are always on the main port too",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="bridge processes sharing the port (SO_REUSEPORT), each its own ROS node "
        "(default 1)",
    )
    p.add_argument(
        "--topic-reader",
        choices=("auto", "thread"),  # rclpy_graph.reader.READERS (that module imports rclpy)
        default="auto",
        help="what waits on the topics: auto (the middleware wakes the event loop itself, on "
        "Linux x86-64 and AArch64 with rmw_fastrtps; a thread elsewhere) or thread "
        "(default auto)",
    )
    eventloop.add_argument(p, "bridge")
    p.add_argument(
        "--no-websocket",
        action="store_true",
        help="open no websocket listener (a robot reached only through Zenoh relays, "
        "--zenoh-connect: it needs no open port)",
    )
    p.add_argument(
        "--robot",
        default=None,
        help="this robot's name on Zenoh (its keys are under NAME/; with --zenoh-connect)",
    )
    p.add_argument(
        "--relay-role",
        default=None,
        metavar="ROLE",
        help="with --zenoh-connect: the role of --auth-file that every relay is held to on "
        "this robot (what topics, services, actions and parameters relays may reach, and "
        "take_over of names ROS nodes serve); default: everything but take_over",
    )
    p.add_argument(
        "--relay-replay-count",
        type=int,
        default=DEFAULT_REPLAY_COUNT,
        metavar="N",
        help="with --zenoh-connect: messages of each reliable topic kept for relays whose "
        "link drops, sent to them once it is back (default %(default)s; 0: none)",
    )
    p.add_argument(
        "--relay-replay-bytes",
        type=int,
        default=DEFAULT_REPLAY_BYTES,
        metavar="BYTES",
        help="with --zenoh-connect: payload bytes of each reliable topic kept so at most "
        "(default %(default)s, 8 MiB)",
    )
    p.add_argument(
        "--relay-replay-total-bytes",
        type=int,
        default=DEFAULT_REPLAY_TOTAL_BYTES,
        metavar="BYTES",
        help="with --zenoh-connect: payload bytes kept so at most, all reliable topics "
        "together (default %(default)s, 64 MiB; a topic with no room left is not replayed)",
    )
    p.add_argument(
        "--relay-priority",
        action="append",
        default=[],
        metavar="TOPIC=LEVEL",
        help="with --zenoh-connect: the Zenoh priority of TOPIC's messages on the robot's link "
        "(LEVEL: real_time, interactive_high, interactive_low, data_high, data, data_low or "
        "background, +express to send them unbatched; TOPIC * for every topic); by default "
        "chosen from a topic's message size and QoS, small messages first (may be given "
        "several times)",
    )
    p.add_argument("--worker-index", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--worker-dir", default=None, help=argparse.SUPPRESS)
    p.add_argument(
        "--log-level",
        default="INFO",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="logging level (default INFO)",
    )
    decode_budget.add_arguments(p)
    security.add_arguments(p)
    zenoh_link.add_arguments(p, listen=False)
    robot_link.add_arguments(p)
    return p.parse_args(argv)


STOP_DEADLINE = 6.0
"""Seconds the bridge may take to stop once told to; past them it exits at once (status 1,
every thread's traceback on stderr), so a service manager or a supervisor is never left
waiting.

rmw_fastrtps (Jazzy, Fast DDS 2.14) can deadlock while it destroys the bridge's node: one
thread waits, spinning a core, for a discovery callback to finish while holding the lock that
callback needs (the spin is Fast-DDS issue #6513). It takes another ROS process's endpoints
coming or going at that moment, such as the other workers stopping with the same supervisor;
CI saw a worker stuck that way. The watchdog is faulthandler's own thread, which needs no GIL
(the stuck thread holds it)."""


async def _run(args: argparse.Namespace) -> int:
    try:  # the sessions import without the bridge's extra (MockRos runs them); ROS does not
        from bridge_server.front.server import Bridge, BridgeConfig
        from bridge_server.rclpy_graph.graph import RclpyGraph
    except ModuleNotFoundError as missing:
        from bridge_server._requires import missing_dependency

        missing_dependency(missing)

    config = BridgeConfig(
        host=args.host,
        port=args.port,
        max_message_size=args.max_message_size,
        write_limit=args.write_limit,
        compression=args.compression == "deflate",
        publisher_grace=args.publisher_grace,
        topic_reader=args.topic_reader,
        metrics_port=args.metrics_port,
        worker_index=args.worker_index or 0,
        worker_dir=args.worker_dir,
        keepalive_interval=args.keepalive_interval,
        keepalive_timeout=args.keepalive_timeout,
        websocket=not args.no_websocket,
        **({"node_name": args.node_name} if args.node_name else {}),
        session=SessionConfig(
            default_queue_length=args.send_queue,
            call_timeout=args.call_timeout,
            served_call_timeout=args.served_call_timeout,
            goal_timeout=args.goal_timeout,
        ),
        resume=ResumeConfig(
            session_keep=args.session_keep,
            sessions_per_principal=max(1, args.sessions_per_principal),
            resume_frames=max(1, args.resume_frames),
            resume_bytes=max(1, args.resume_bytes),
        ),
        security=security.config_from_args(args),
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    if args.worker_index is not None:
        from bridge_server.workers.supervisor import watch_supervisor

        config.node_name = f"{config.node_name}_w{args.worker_index}"
        watch_supervisor(stop)  # a worker stops with its supervisor, even a killed one
    graph = RclpyGraph(loop, name=config.node_name, topic_reader=config.topic_reader)
    bridge = Bridge(config, graph)
    try:
        await bridge.start()
    except BaseException:  # a port in use: ROS already runs, stop it before saying so
        with contextlib.suppress(Exception):  # what failed to start may not close cleanly
            await bridge.close()
        raise
    exporter = None
    if args.zenoh_connect:  # the robot dials out to Zenoh routers (bridge_server/zenoh/)
        from bridge_server.zenoh.exporter import Exporter

        try:
            policy = relay_policy(bridge, args.relay_role)
        except BridgeError:  # ROS already runs: stop it before saying so
            await bridge.close()
            raise
        exporter = Exporter(bridge.graph, args.robot, robot_link.robot_options(args),
                            graph_changed=bridge.graph_changed, policy=policy,
                            replay=replay_window(args),
                            priorities=parse_overrides(args.relay_priority))
        bridge.web.extra_metrics.append(exporter.metrics)
        bridge.web.extra_status.append(exporter.status)
        if not config.websocket:  # reached only through relays: ready when its uplink is
            bridge.web.readiness = exporter.uplink.not_ready
        exporter.start()
        log.info("robot %s dialing out to Zenoh at %s", args.robot, ", ".join(args.zenoh_connect))
    # SIGHUP (systemctl reload): certificates and the auth file are read again.
    loop.add_signal_handler(signal.SIGHUP, bridge.reload)
    if args.worker_index is not None:  # the supervisor prints the bridge's ready line
        log.info("bridge_server worker %d listening", args.worker_index)
    elif not config.websocket:
        log.info("bridge_server running without a websocket listener")
    else:
        scheme = "wss" if args.certfile else "ws"
        log.info("bridge_server listening on %s://%s:%d", scheme, args.host, bridge.port)
    log.info("event loop: %s", eventloop.loop_name(loop))
    log.info("ROS node /%s on ROS_DOMAIN_ID %s (topic reader: %s)", config.node_name,
             os.environ.get("ROS_DOMAIN_ID", "0"), graph.reader_kind)
    bridge.security.startup_warnings(args.host)
    await stop.wait()
    log.info("bridge_server shutting down")
    # Not cancelled: it covers the rest of the process's exit too.
    faulthandler.dump_traceback_later(STOP_DEADLINE, exit=True)
    if exporter is not None:
        await exporter.close()
    await bridge.close()
    return 0


def replay_window(args: argparse.Namespace) -> ReplayWindow:
    """The replay window the ``--relay-replay-*`` options give; ``ValueError`` naming one
    that does not fit."""
    return ReplayWindow(args.relay_replay_count, args.relay_replay_bytes,
                        args.relay_replay_total_bytes)


def relay_policy(bridge: Bridge, role: str | None) -> Callable[[], Role | None]:
    """The robot's relay policy: ``role`` of the bridge's auth file, looked up at each
    request (SIGHUP reads the file again), or the exporter's default without one.
    ``BridgeError`` at start if the file has no such role."""
    from bridge_server.zenoh.exporter import DEFAULT_POLICY

    if role is None:
        return lambda: DEFAULT_POLICY
    auth = bridge.security.auth
    if auth is None or role not in auth.roles:
        known = ", ".join(auth.roles) if auth is not None else "none"
        raise BridgeError(f"--relay-role {role}: no such role in the auth file (roles: {known})")
    log.info("relays are held to role %s of the auth file on this robot", role)
    def current() -> Role | None:
        reloaded = bridge.security.auth
        return reloaded.roles.get(role) if reloaded is not None else None

    return current


@ends_process
def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bridge_server`` and ``roslibpy-lite-bridge``: without
    ``argv`` it ends the process with its status (:func:`~bridge_server._exit.ends_process`),
    with one it returns the status."""
    command = (sys.argv[1:] if argv is None else argv)[:1]
    if command in (["add-principal"], ["remove-principal"]):
        from rosbridge_core.security.auth import main as principals

        return principals(sys.argv[1:] if argv is None else argv)
    if command == ["healthcheck"]:
        from bridge_server.healthcheck import main as healthcheck

        return healthcheck((sys.argv[1:] if argv is None else argv)[1:], parse_args)
    args = parse_args(argv)
    tune_allocator()
    refusal = security.exposure_refusal(args)
    if refusal is None and args.zenoh_connect and args.robot is None:
        refusal = "--zenoh-connect needs --robot NAME (the robot's name on Zenoh)"
    if refusal is None and args.robot is not None:
        try:
            check_robot(args.robot)
        except BridgeError as exc:
            refusal = f"--robot: {exc}"
    if refusal is None and args.zenoh_connect:
        refusal = zenoh_link.options_from_args(args).refusal()
    if refusal is None:
        try:
            replay_window(args)
            parse_overrides(args.relay_priority)
            decode_budget.apply(args)
        except ValueError as exc:
            refusal = str(exc)
    if refusal is None and args.zenoh_connect:
        refusal = robot_link.options_refusal(robot_link.robot_options(args))
    if refusal is None and args.relay_role is not None and not (
            args.zenoh_connect and args.auth_file):
        refusal = ("--relay-role names a role of --auth-file that relays are held to: it "
                   "needs --auth-file and --zenoh-connect")
    if refusal is not None:
        print(f"roslibpy-lite-bridge: refusing to start: {refusal}", file=sys.stderr)
        return 2
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    logging.basicConfig(
        level=getattr(logging, args.log_level),
        stream=sys.stderr,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    security.install_log_redaction()  # tokens never reach the log, whoever logs them
    if args.log_level != "DEBUG":
        logging.getLogger("websockets").setLevel(logging.WARNING)
    try:
        checked = security.config_from_args(args)
        security.check_readable(checked)  # names the file and user
        # A file that is no certificate (or auth file) is named before ROS starts.
        Security(checked).ssl_context()
        if args.workers > 1 and args.worker_index is None:
            from bridge_server.workers.supervisor import Supervisor

            argv = sys.argv[1:] if argv is None else argv
            return Supervisor(argv, args.workers, args.host, args.port, args.metrics_port).run()
        with asyncio.Runner(loop_factory=eventloop.event_loop_factory(args.event_loop)) as runner:
            return runner.run(_run(args))
    except (OSError, BridgeError) as exc:  # a port in use, an unreadable auth/cert file, ...
        log.error("cannot start: %s", exc)
        return 1


if __name__ == "__main__":
    sys.exit(main())
