"""The CLI examples from ``--help`` (and the README) run against the demo's parts and work."""

from __future__ import annotations

import re
import shlex
import sys
import threading
from typing import Any

from roslibpy_lite.cli import EXAMPLES
from tests.cli.conftest import Run
from tests.examples.support import Program
from tests.helpers import BridgeProcess, wait_until

# What each example must print (a regex searched in its stdout).
EXPECT = {
    "topic list -t": r"(?m)^/example_counter \[std_msgs/msg/Int16\]$",
    "topic echo /example_counter --count 3": r"\Adata: -?\d+\n---\ndata: -?\d+\n---\ndata: -?\d+\n---\n\Z",
    'topic pub /chatter std_msgs/msg/String "{data: hello}" --once':
        r'\Apublishing #1: \{"data": "hello"\}\n\Z',
    "topic hz /imu --duration 3": r"(?m)^average rate: \d+\.\d{3}\n\tmin: .* window: \d+$",
    'service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"': r"\Aresult: 10\.0\n\Z",
    'action send_goal /integrate_imu mult_msgs/action/IntegrateImu "{seconds: 0.5}" --feedback':
        r"(?s)\ASending goal:\n  seconds: 0\.5\n.*Result:\n  total:\n.*samples: \d+\n"
        r"\nGoal finished with status: SUCCEEDED\n\Z",
    "node list": r"(?m)^/roslibpy_lite_bridge_\d+$",
    "interface show sensor_msgs/msg/Imu":
        r"(?m)^geometry_msgs/Vector3 angular_velocity\n(\t#.*\n|\n)*\tfloat64 x$",
}


def test_every_help_example_works(cli: Run, bridge: BridgeProcess, ros_node: Any) -> None:
    """With robot_app, an IMU publisher and a /chatter listener up, each example exits 0 as shown."""
    from sensor_msgs.msg import Imu
    from std_msgs.msg import String

    assert set(EXPECT) == set(EXAMPLES), "every example needs an expectation here"
    imu_pub = ros_node.create_publisher(Imu, "/imu", 10)
    timer = ros_node.create_timer(1 / 50, lambda: imu_pub.publish(Imu()))
    heard = threading.Event()
    ros_node.create_subscription(String, "/chatter", lambda m: heard.set(), 10)
    app = Program([sys.executable, "-m", "examples.robot_app", "--url", bridge.url])
    try:
        app.wait_for(r"^\[service\] serving /mult_floats")
        app.wait_for(r"^\[action\] serving /integrate_imu")
        wait_until(lambda: "/example_counter" in cli("topic", "list").out, timeout=15,
                   what="the counter topic in the graph")
        for example in EXAMPLES:
            result = cli(*shlex.split(example))
            assert result.code == 0, (example, result)
            assert re.search(EXPECT[example], result.out), (example, result.out)
        assert heard.wait(10), "the /chatter listener heard nothing"
    finally:
        ros_node.destroy_timer(timer)
        assert app.interrupt() == 0, app.dump()
