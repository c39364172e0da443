"""The sample application's action end to end: an rclpy action client sends /integrate_imu a goal
through the real bridge while an rclpy publisher feeds /imu."""

from __future__ import annotations

import importlib
import sys
import threading
from typing import Any

from tests.examples.support import Program
from tests.helpers import BridgeProcess, action_server_answers, wait_until


def test_integrate_imu_from_rclpy(bridge: BridgeProcess, ros_node: Any) -> None:
    """An rclpy goal of 1 s gets feedback with a growing sum and a SUCCEEDED result with samples."""
    from action_msgs.msg import GoalStatus
    from mult_msgs.action import IntegrateImu
    from sensor_msgs.msg import Imu

    action: Any = importlib.import_module("rclpy.action")
    imu_pub = ros_node.create_publisher(Imu, "/imu", 10)

    def publish_imu() -> None:
        msg = Imu()
        msg.angular_velocity.x = 0.5
        imu_pub.publish(msg)

    timer = ros_node.create_timer(1 / 50, publish_imu)
    client = action.ActionClient(ros_node, IntegrateImu, "/integrate_imu")
    app = Program([sys.executable, "-m", "examples.robot_app", "--url", bridge.url])
    try:
        app.wait_for(r"^\[action\] serving /integrate_imu \(mult_msgs/action/IntegrateImu\)$")
        wait_until(action_server_answers(client), 15, "/integrate_imu to answer")
        sums: list[float] = []
        answered = threading.Event()
        goal_future = client.send_goal_async(
            IntegrateImu.Goal(seconds=1.0),
            feedback_callback=lambda fb: sums.append(fb.feedback.sum.x))
        goal_future.add_done_callback(lambda _: answered.set())
        assert answered.wait(15), "the goal was never answered"
        handle = goal_future.result()
        assert handle.accepted
        finished = threading.Event()
        result_future = handle.get_result_async()
        result_future.add_done_callback(lambda _: finished.set())
        assert finished.wait(15), "no result"
        response = result_future.result()
        assert response.status == GoalStatus.STATUS_SUCCEEDED
        assert response.result.samples >= 10
        # 0.5 rad/s for about 1 s (the first sample's dt counts from the goal's start)
        assert 0.3 < response.result.total.x < 0.7, response.result
        assert len(sums) >= 5 and sums == sorted(sums)
        app.wait_for(r"^\[action\] /integrate_imu: done: total=\(\+0\.\d+, ")
    finally:
        client.destroy()
        ros_node.destroy_timer(timer)
        code = app.interrupt()
    assert code == 0, app.dump()
    assert app.err == [], app.dump()
