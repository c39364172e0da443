"""A robot's link under load, for the relay tests: real processes, the link through a proxy.

A relay that is the Zenoh router, a robot's bridge (``--no-websocket``) dialing it through a
:class:`~bench.linkproxy.LinkProxy` (latency, bandwidth, blackhole), and an rclpy node on the
robot publishing a counter (``/outage/count``, reliable; ``/load/imu`` and ``/load/camera``,
sensor-data QoS, when asked). What our client hears is timed as it arrives.
"""

from __future__ import annotations

import contextlib
import itertools
import re
import sys
import textwrap
from collections.abc import Iterator

from bench.linkproxy import LinkProxy
from tests.helpers import free_port, ros_env
from tests.relay.procs import Proc, until_robot_served
from tests.relay.test_relay_outage import ROBOT, TOPIC, Outage

__all__ = ["CAMERA", "COUNT", "IMU", "ROBOT", "Loaded", "gaps", "load_tier", "p99"]

Loaded = Outage
"""The relay, the link, the robot's bridge and its counter's node (``sent()``: the last
number it reported, once a second here)."""

COUNT = TOPIC
"""The counter (the outage tests' topic, so their clients' helpers serve here too)."""
IMU = "/load/imu"
CAMERA = "/load/camera"
READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")

PUBLISHER = textwrap.dedent("""
    import sys

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image, Imu
    from std_msgs.msg import String

    hz, imu, camera = float(sys.argv[1]), sys.argv[2] == "1", sys.argv[3] == "1"
    rclpy.init()
    node = rclpy.create_node("load_publisher")
    count = node.create_publisher(String, sys.argv[4], 10)  # reliable: replayed
    n = [0]

    def tick():
        n[0] += 1
        count.publish(String(data=str(n[0])))
        if n[0] % max(1, int(hz)) == 0:
            print(f"sent {n[0]}", flush=True)

    if hz:
        node.create_timer(1.0 / hz, tick)
    if imu:
        imu_pub = node.create_publisher(Imu, "/load/imu", qos_profile_sensor_data)
        node.create_timer(0.01, lambda: imu_pub.publish(Imu()))
    if camera:
        cam_pub = node.create_publisher(Image, "/load/camera", qos_profile_sensor_data)
        frame = Image(height=480, width=640, encoding="rgb8", step=640 * 3,
                      data=bytes(640 * 480 * 3))
        node.create_timer(0.1, lambda: cam_pub.publish(frame))
    print("publishing", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
""")


@contextlib.contextmanager
def load_tier(*robot_options: str, hz: float = 10.0, imu: bool = False,
              camera: bool = False) -> Iterator[Loaded]:
    """The tier (see the module's text), the robot given ``robot_options``; yields once the
    relay serves the robot and the counter runs."""
    zport, port = free_port(), free_port()
    procs: list[Proc] = []
    try:
        procs.append(Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port",
                           str(port), "--zenoh-listen", f"tcp/127.0.0.1:{zport}"], ros_env()))
        procs[0].wait_for(READY)
        with LinkProxy(("127.0.0.1", zport)) as link:
            procs.append(Proc([sys.executable, "-m", "bridge_server", "--no-websocket",
                               "--robot", ROBOT, "--zenoh-connect",
                               f"tcp/127.0.0.1:{link.port}", *robot_options], ros_env()))
            procs[1].wait_for(re.compile(rf"robot {ROBOT} is on Zenoh"))
            # the camera in a process of its own: its frames do not delay the counter's timer
            for args in (("0", "0", "1"),) if camera else ():
                procs.append(Proc([sys.executable, "-c", PUBLISHER, *args, COUNT], ros_env()))
            procs.append(Proc([sys.executable, "-c", PUBLISHER, str(hz), str(int(imu)), "0",
                               COUNT], ros_env()))
            for p in procs[2:]:
                p.wait_for(re.compile("^publishing"))
            until_robot_served(port, ROBOT)
            yield Outage(procs[0], link, procs[1], procs[-1], port)
    finally:
        for p in reversed(procs):
            p.stop()


def gaps(times: list[float]) -> list[float]:
    """The seconds between consecutive arrivals."""
    return [b - a for a, b in itertools.pairwise(times)]


def p99(values: list[float]) -> float:
    """The 99th percentile (nearest rank) of ``values``."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
