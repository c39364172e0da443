"""A robot behind NAT, served through a relay: a small rclpy node and the bridge in robot mode.

What a robot operator runs on a robot that accepts no inbound connection (the relay guide's
quick start, ``docs/guides/relay.md``): this program starts the robot's bridge as a child
process (``python -m bridge_server --no-websocket --robot NAME`` plus the Zenoh options
given after ``--``: it dials out to the relay and opens no port) and runs a small rclpy node
beside it, which clients reach through the relay as ``wss://relay:9090/NAME``:

- ``/robot_status`` (``std_msgs/msg/String``), the robot's name and a count, twice a second;
- ``/robot_ping`` (``std_srvs/srv/Trigger``), answering ``pong from NAME``.

Run it with the robot's certificate from ``roslibpy-lite-relay certs``::

    python -m examples.relay_robot robot1 -- --zenoh-connect tls/relay.example.com:7447 \\
        --zenoh-tls-ca fleet/ca.pem --zenoh-tls-cert fleet/robot1.pem \\
        --zenoh-tls-key fleet/robot1.key

Replace the node with your own; the bridge needs nothing of it. Ctrl+C (or SIGTERM) stops
both with exit status 0; if the bridge exits (a refused option, a missing certificate) the
program ends with the bridge's status, its log already on stderr.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from types import FrameType
from typing import Any

__all__ = ["bridge_command", "main", "make_node"]

STATUS_PERIOD = 0.5
"""Seconds between two ``/robot_status`` messages."""


def bridge_command(robot: str, bridge_args: list[str]) -> list[str]:
    """The robot's bridge: robot mode, no listening port, dialing out with ``bridge_args``."""
    return [sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", robot,
            *bridge_args]


def make_node(robot: str, context: Any) -> Any:
    """The robot's rclpy node: ``/robot_status`` twice a second and the ``/robot_ping``
    service (in ``context``)."""
    from rclpy.node import Node
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    node = Node(f"{robot}_example", context=context)
    status = node.create_publisher(String, "/robot_status", 10)
    sent = [0]

    def tick() -> None:
        sent[0] += 1
        status.publish(String(data=f"{robot} ok {sent[0]}"))

    def ping(_request: Any, response: Any) -> Any:
        response.success, response.message = True, f"pong from {robot}"
        return response

    node.create_timer(STATUS_PERIOD, tick)
    node.create_service(Trigger, "/robot_ping", ping)
    return node


def main(argv: list[str] | None = None) -> int:
    """``python -m examples.relay_robot NAME -- BRIDGE_OPTIONS...``: run both until a signal
    (0) or until the bridge exits (its status)."""
    argv = sys.argv[1:] if argv is None else argv
    robot, rest = (argv[0], argv[1:]) if argv else ("", [])
    if not robot or robot.startswith("-"):
        print("usage: python -m examples.relay_robot NAME -- --zenoh-connect ENDPOINT ...",
              file=sys.stderr)
        return 2
    bridge_args = rest[1:] if rest[:1] == ["--"] else rest
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    bridge = subprocess.Popen(bridge_command(robot, bridge_args))
    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = make_node(robot, context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    print(f"robot {robot}: node {node.get_name()} up, bridge pid {bridge.pid}", file=sys.stderr)
    try:
        while not stop.is_set() and bridge.poll() is None:
            executor.spin_once(timeout_sec=0.2)
    finally:
        executor.remove_node(node)
        node.destroy_node()
        rclpy.shutdown(context=context)
    if bridge.poll() is None:  # stopped by a signal: stop the bridge too
        bridge.terminate()
        try:
            bridge.wait(10)
        except subprocess.TimeoutExpired:
            bridge.kill()
            bridge.wait()
        return 0
    # The bridge ended: with us (Ctrl+C reaches the whole process group), or on its own.
    return 0 if stop.is_set() else (bridge.returncode or 1)


if __name__ == "__main__":
    sys.exit(main())
