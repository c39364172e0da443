"""The sample application end to end: real bridge, real rclpy peers, the program as a subprocess."""

from __future__ import annotations

import re
import sys
import threading
from typing import Any

from tests.examples.support import Program
from tests.helpers import BridgeProcess, wait_until


def test_robot_app_against_ros(bridge: BridgeProcess, ros_node: Any) -> None:
    """ROS hears the counter, the program sums the IMU it is sent, and ROS can call /mult_floats."""
    from mult_msgs.srv import MultFloats
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Int16

    counts: list[int] = []
    ros_node.create_subscription(Int16, "/example_counter", lambda m: counts.append(m.data), 10)
    imu_pub = ros_node.create_publisher(Imu, "/imu", 10)

    def publish_imu() -> None:
        msg = Imu()
        msg.angular_velocity.x = 0.5
        imu_pub.publish(msg)

    timer = ros_node.create_timer(1 / 50, publish_imu)
    app = Program([sys.executable, "-m", "examples.robot_app", "--url", bridge.url])
    try:
        app.wait_for(r"^\[app\] connected to ws://127\.0\.0\.1:\d+$")
        # The IMU sums: every message adds 0.5, so line #n shows sum 0.5 * n. The summer
        # prints the first message, then the latest at most once a second (#50 or so).
        app.wait_for(r"^\[imu\] #[1-9]\d+ ")
        imu_lines = [m for line in app.out if (m := re.match(
            r"^\[imu\] #(\d+) angular_velocity\.x=([+-][\d.]+) sum=([+-][\d.]+)$", line))]
        assert len(imu_lines) >= 2 and int(imu_lines[-1][1]) >= 10
        for m in imu_lines:
            n, x, total = int(m[1]), float(m[2]), float(m[3])
            assert x == 0.5 and total == 0.5 * n, m[0]

        # The counter, seen by an rclpy subscriber: consecutive integers.
        wait_until(lambda: len(counts) >= 2, timeout=15, what="two counter messages")
        assert counts == list(range(counts[0], counts[0] + len(counts)))

        # The service, called by an rclpy client.
        client = ros_node.create_client(MultFloats, "/mult_floats")
        assert client.wait_for_service(timeout_sec=15), "no /mult_floats in the ROS graph"
        done = threading.Event()
        future = client.call_async(MultFloats.Request(x=2.5, y=4.0))
        future.add_done_callback(lambda _: done.set())
        assert done.wait(15), "no answer from /mult_floats"
        assert future.result().result == 10.0
        app.wait_for(r"^\[service\] /mult_floats: 2\.5 \* 4\.0 = 10\.0$")
        ros_node.destroy_client(client)
    finally:
        ros_node.destroy_timer(timer)
        code = app.interrupt()
    assert code == 0, app.dump()
    assert app.out[-1] == "[app] stopped"
    assert app.err == [], app.dump()


def test_imu_sim_publishes_a_changing_angular_velocity(ros_node: Any) -> None:
    """examples.imu_sim publishes sensor_msgs/Imu on /imu whose angular velocity changes, then exits 0."""
    from sensor_msgs.msg import Imu

    xs: list[float] = []
    lock = threading.Lock()

    def on_imu(msg: Any) -> None:
        with lock:
            xs.append(msg.angular_velocity.x)

    ros_node.create_subscription(Imu, "/imu", on_imu, 50)
    sim = Program([sys.executable, "-m", "examples.imu_sim", "--rate", "50", "--count", "100"])
    try:
        sim.wait_for(r"^\[imu_sim\] publishing sensor_msgs/msg/Imu on /imu at 50 Hz$")
        wait_until(lambda: len(set(xs)) >= 3, timeout=15, what="three different readings")
        assert sim.proc.wait(30) == 0, sim.dump()
    finally:
        sim.kill()
    assert sim.out[-1] == "[imu_sim] stopped after 100 messages"
    assert all(-0.5 <= x <= 0.5 for x in xs)
