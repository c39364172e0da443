"""The in-memory Graph and the session run in a client-only install: no rclpy, Zenoh, cbor2,
prometheus_client or pybase64 is imported to build a graph, publish, serve and call, nor to
import the session and what it counts in."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from tests.core.test_import_cycles import ROOT

ABSENT = ("rclpy", "zenoh", "cbor2", "prometheus_client", "pybase64")
"""What a ``pip install roslibpy-lite`` (websockets only) does not have."""

_PROGRAM = textwrap.dedent("""
    import asyncio, sys
    for name in sys.argv[1:]:
        sys.modules[name] = None  # importing it raises ImportError, as if not installed
    from rosbridge_core.memory.graph import MemoryRos
    import rosbridge_core.session.session, rosbridge_core.counters

    async def main():
        ros = MemoryRos()
        robot, bridge = ros.node("robot"), ros.node("bridge")
        string = bridge.resolve_message("std_msgs/msg/String")
        got = []
        bridge.subscribe("/chat", string, got.append)
        pub = robot.acquire_publisher("/chat", string, False, 10)
        pub.publish(pub.conv.from_obj({"data": "hi"}))
        srv = robot.resolve_service("std_srvs/srv/Trigger")
        robot.serve("/go", srv, lambda call: call.complete())
        answer = await bridge.call_service("/go", None, {}, 1.0, 0.1)
        print(got[0].json_text())
        print(answer)
        print(bridge.typedefs("std_msgs/String", "msg")[0]["type"])

    asyncio.run(main())
""")


def test_memory_graph_needs_none_of_the_bridges_dependencies() -> None:
    """Topics, services and typedefs work, and the session imports, with each of ABSENT made
    unimportable."""
    out = subprocess.run([sys.executable, "-c", _PROGRAM, *ABSENT], cwd=ROOT, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines() == [
        '{"op":"publish","topic":"/chat","msg":{"data":"hi"}}',
        "{'success': False, 'message': ''}",
        "std_msgs/msg/String",
    ]
