"""Several bridges on one ROS domain: distinct node names, and lookups that never mix them up."""

from __future__ import annotations

from typing import Any

import pytest
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from tests.helpers import BridgeProcess, WireClient, open_wire, rosapi, rosapi_until, roundtrip
from tests.security.support import make_auth_file, wire


async def _until_listed(ws: WireClient, service: str, key: str, name: str) -> None:
    await rosapi_until(ws, service, None, lambda values: name in values[key], timeout=10)


@pytest.mark.parametrize("same_name", [False, True])
async def test_two_bridges_see_the_whole_graph(
    make_bridge: Any, tmp_path: Any, ros_node: Any, topic: str, same_name: bool
) -> None:
    """A loopback bridge and a secured one on one domain each list and type an rclpy service,
    an rclpy action and a service a client of the other bridge serves; by default their node
    names differ, and lookups hold even when both are given the same --node-name."""
    from rclpy.action.server import ActionServer

    auth = make_auth_file(tmp_path)
    extra = ["--node-name", "twin_bridge"] if same_name else []
    plain = make_bridge(*extra)
    secured = make_bridge("--auth-file", str(auth.path), *extra)
    if not same_name:
        assert plain.node_name != secured.node_name
    service, action, served = topic + "_srv", topic + "_act", topic + "_served"
    ros_node.create_service(SetBool, service, lambda q, r: r)
    server = ActionServer(ros_node, Fibonacci, action, lambda goal: Fibonacci.Result())  # type: ignore[no-untyped-call]
    a = await open_wire(plain.url)
    b = await wire(secured.url, auth.tokens["admin"])
    try:
        await a.send({"op": "advertise_service", "service": served,
                      "type": "std_srvs/srv/SetBool"})
        await roundtrip(a)
        for ws in (a, b):
            await _until_listed(ws, "/rosapi/services", "services", service)
            await _until_listed(ws, "/rosapi/services", "services", served)
            await _until_listed(ws, "/rosapi/action_servers", "action_servers", action)
            for name in (service, served):
                values = await rosapi(ws, "/rosapi/service_type", {"service": name})
                assert values == {"type": "std_srvs/srv/SetBool"}
        # A call through the secured bridge reaches the service a client of the other serves.
        await b.send({"op": "call_service", "service": served, "type": "std_srvs/srv/SetBool",
                      "args": {"data": True}, "id": "c", "timeout": 30})
        request = await a.expect(op="call_service", service=served)
        await a.send({"op": "service_response", "service": served, "id": request["id"],
                      "result": True, "values": {"success": True, "message": "from a"}})
        reply = await b.expect(op="service_response", id="c")
        assert reply["values"] == {"success": True, "message": "from a"}
    finally:
        await a.close()
        await b.close()
        server.destroy()  # type: ignore[no-untyped-call]


def test_node_name_option_and_default(make_bridge: Any) -> None:
    """--node-name sets the bridge's node name; without it the name carries the process id."""
    named: BridgeProcess = make_bridge("--node-name", "robot_a_bridge")
    assert named.node_name == "/robot_a_bridge"
    default: BridgeProcess = make_bridge()
    assert default.node_name.startswith("/roslibpy_lite_bridge_")
    assert default.proc is not None and default.node_name.endswith(f"_{default.proc.pid}")
