"""A plain rclpy node for the mixed-distribution tests, run by whichever venv's Python starts
it (Jazzy's or Kilted's): it republishes each std_msgs/String of ``PREFIX/in`` on
``PREFIX/out`` with its distribution in front, serves ``PREFIX/srv`` (std_srvs/SetBool) the
same way, and publishes one sensor_msgs/Image on ``PREFIX/image`` a second.

    python -m tests.distro.echo_peer PREFIX

It prints ``echo peer ready DISTRO RCLPY_VERSION`` once its entities exist, and the type hash
of every publisher it sees on ``PREFIX/in`` as ``in-hash HASH`` (the other side's view).
"""

from __future__ import annotations

import contextlib
import os
import sys
from importlib.metadata import version
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import Image
from std_msgs.msg import String
from std_srvs.srv import SetBool

DISTRO = {"7": "jazzy", "9": "kilted"}.get(version("ros-rclpy").split(".")[0], "unknown")
"""This Python's ROS 2 distribution, told by its rclpy's major version."""


def main(prefix: str) -> None:
    """Run the node until interrupted."""
    rclpy.init()
    node = rclpy.create_node("echo_peer")
    out = node.create_publisher(String, f"{prefix}/out", 10)
    image_pub = node.create_publisher(Image, f"{prefix}/image", 10)

    def echo(msg: Any) -> None:
        out.publish(String(data=f"{DISTRO}:{msg.data}"))

    def answer(request: Any, response: Any) -> Any:
        response.success = bool(request.data)
        response.message = DISTRO
        return response

    def image() -> None:
        frame = Image(height=2, width=3, encoding="mono8", step=3, data=bytes(range(6)))
        frame.header.frame_id = DISTRO
        image_pub.publish(frame)

    hashes: set[str] = set()

    def watch() -> None:
        for info in node.get_publishers_info_by_topic(f"{prefix}/in"):
            seen = str(getattr(info, "topic_type_hash", "none"))
            if seen not in hashes:
                hashes.add(seen)
                print(f"in-hash {seen}", flush=True)

    node.create_subscription(String, f"{prefix}/in", echo, 10)
    node.create_service(SetBool, f"{prefix}/srv", answer)
    node.create_timer(1.0, image)
    node.create_timer(0.2, watch)
    print(f"echo peer ready {DISTRO} {version('ros-rclpy')}", flush=True)
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)


if __name__ == "__main__":
    main(sys.argv[1])
