"""The robot side of the demo: an rclpy node publishing ``sensor_msgs/msg/Imu`` on ``/imu``.

This is ROS code (it imports rclpy) and stays out of roslibpy_lite. It
publishes at 50 Hz by default; the angular velocity turns slowly
(``x = 0.5 * sin(t)``, ``y = 0.5 * cos(t)``, ``z = 0.1``), so sums change.

    python -m examples.imu_sim --rate 50

Ctrl+C (or SIGTERM) stops it with exit status 0. DDS discovery stays on this
machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) unless the environment
says otherwise.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any

__all__ = ["main", "make_imu"]


def make_imu(imu_cls: Any, t: float, frame_id: str = "imu_link") -> Any:
    """One Imu message (an instance of rclpy's ``imu_cls``) for time ``t`` (seconds)."""
    msg = imu_cls()
    sec = math.floor(t)
    msg.header.stamp.sec = int(sec)
    msg.header.stamp.nanosec = int((t - sec) * 1e9)
    msg.header.frame_id = frame_id
    msg.orientation.w = 1.0
    msg.angular_velocity.x = 0.5 * math.sin(t)
    msg.angular_velocity.y = 0.5 * math.cos(t)
    msg.angular_velocity.z = 0.1
    msg.linear_acceleration.z = 9.81
    return msg


def main(argv: Sequence[str] | None = None) -> int:
    """Publish until SIGINT/SIGTERM (or ``--count`` messages); returns the exit status."""
    p = argparse.ArgumentParser(
        prog="python -m examples.imu_sim", description="Publish sensor_msgs/msg/Imu on /imu."
    )
    p.add_argument("--topic", default="/imu", help="topic (default /imu)")
    p.add_argument("--rate", type=float, default=50.0, help="messages per second (default 50)")
    p.add_argument("--count", type=int, default=0, help="stop after this many (0: never)")
    args = p.parse_args(argv)
    if args.rate <= 0:
        p.error("--rate must be > 0")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import Imu

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("imu_sim")
    pub = node.create_publisher(Imu, args.topic, 10)
    stop = threading.Event()
    sent = 0

    def tick() -> None:
        nonlocal sent
        now = node.get_clock().now().nanoseconds / 1e9
        pub.publish(make_imu(Imu, now))
        sent += 1
        if args.count and sent >= args.count:
            stop.set()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node.create_timer(1.0 / args.rate, tick)
    print(f"[imu_sim] publishing sensor_msgs/msg/Imu on {args.topic} at {args.rate:g} Hz",
          flush=True)
    try:
        while not stop.is_set():
            rclpy.spin_once(node, timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    finally:
        node.destroy_node()  # type: ignore[no-untyped-call]
        rclpy.utilities.try_shutdown()
    print(f"[imu_sim] stopped after {sent} messages", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
