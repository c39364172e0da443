"""Past one robot: one bridge per robot, and one program holding a connection to each.

Each robot runs its own bridge (its own ROS graph, its own port); a fleet
program connects to all of them at once with :func:`roslibpy_lite.connect`,
one :class:`~roslibpy_lite.Client` per robot. Each connection reconnects on
its own, so a robot that drops off the network does not disturb the others.

Run it against two bridges::

    python -m examples.multi_robot --robot alpha=ws://10.0.0.5:9090 \\
        --robot beta=ws://10.0.0.6:9090 --command "return to dock"

For every robot it prints the ROS distribution and topic count its bridge
reports, sends ``--command`` (a latched ``std_msgs/msg/String``) on
``--command-topic``, then prints each message of ``--topic`` tagged with the
robot's name, until ``--count`` messages came from every robot (0: until
Ctrl+C).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Sequence

import roslibpy_lite

__all__ = ["main", "watch_robot"]


async def watch_robot(name: str, url: str, topic: str, command_topic: str, command: str | None,
                      count: int) -> None:
    """Connect to one robot's bridge, send the command, print ``count`` messages of ``topic``."""
    async with roslibpy_lite.connect(url) as ros:
        version = await ros.call_service("/rosapi/get_ros_version",
                                         "rosapi_msgs/srv/GetROSVersion", {})
        topics = await ros.call_service("/rosapi/topics", "rosapi_msgs/srv/Topics", {})
        print(f"[{name}] connected to {url}: ROS {version['version']} {version['distro']}, "
              f"{len(topics['topics'])} topics", flush=True)
        # Latched: a robot node that subscribes later still gets the command.
        async with ros.advertise(command_topic, "std_msgs/msg/String", latch=True) as pub:
            if command is not None:
                await pub.publish({"data": f"{command} (to {name})"})
            seen = 0
            async with ros.subscribe(topic, "std_msgs/msg/String") as sub:
                async for msg in sub:
                    seen += 1
                    print(f"[{name}] {topic}: {msg['data']}", flush=True)
                    if count and seen >= count:
                        return


async def _run(args: argparse.Namespace) -> int:
    robots = []
    for spec in args.robot:
        name, sep, url = spec.partition("=")
        if not sep or not name or not url:
            print(f"--robot {spec!r}: expected NAME=ws://HOST:PORT", file=sys.stderr)
            return 2
        robots.append((name, url))
    results = await asyncio.gather(
        *(watch_robot(name, url, args.topic, args.command_topic, args.command, args.count)
          for name, url in robots),
        return_exceptions=True,
    )
    failed = 0
    for (name, _url), result in zip(robots, results, strict=True):
        if isinstance(result, BaseException):
            failed += 1
            print(f"[{name}] failed: {type(result).__name__}: {result}", file=sys.stderr)
    return 1 if failed else 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    p.add_argument("--robot", action="append", required=True, metavar="NAME=URL",
                   help="a robot's bridge, e.g. alpha=ws://10.0.0.5:9090 (repeat per robot)")
    p.add_argument("--topic", default="/status", help="std_msgs/String topic to watch")
    p.add_argument("--command-topic", default="/fleet/command", help="where --command goes")
    p.add_argument("--command", default=None, help="text sent once to every robot")
    p.add_argument("--count", type=int, default=0,
                   help="stop after this many messages from every robot (0: run until Ctrl+C)")
    args = p.parse_args(argv)
    try:
        return asyncio.run(_run(args))
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
