"""Roles: each capability denied for a role that lacks it, with nothing reaching ROS."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable
from typing import Any

import pytest
from std_msgs.msg import String
from std_srvs.srv import SetBool

from rosbridge_core.security.permissions import MAY, Role, RoleError
from tests.bridge.support import Inbox, publish_until_heard, wait_publishers
from tests.helpers import BridgeProcess, roundtrip
from tests.security.support import bridge_entities

Connect = Callable[..., Any]


async def _forbidden(ws: Any, id: str, role: str, capability: str, name: str) -> dict[str, Any]:
    status = await ws.expect(op="status", id=id)
    assert status["level"] == "error"
    assert "forbidden" in status["msg"] and role in status["msg"]
    assert capability in status["msg"] and name in status["msg"]
    return dict(status)


async def test_viewer_publish_is_forbidden_and_reaches_no_ros_node(
    connect_as: Connect, ros_node: Any, topic: str
) -> None:
    """A viewer's advertise and publish are refused; an rclpy subscriber only gets what others send."""
    inbox = Inbox()
    sub = ros_node.create_subscription(String, topic, lambda m: inbox(m.data), 10)
    admin = await connect_as("admin")
    await admin.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"})
    await wait_publishers(sub)
    viewer = await connect_as("viewer")
    await viewer.send({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String",
                       "id": "adv"})
    await _forbidden(viewer, "adv", "viewer", "publish", topic)
    await viewer.send({"op": "publish", "topic": topic, "msg": {"data": "viewer"}, "id": "pub"})
    await _forbidden(viewer, "pub", "viewer", "publish", topic)
    # The first value heard is the admin's: the viewer's publish never reached ROS.
    assert await publish_until_heard(admin, topic, {"data": "marker"}, inbox) == "marker"


async def test_call_service_forbidden_never_reaches_the_service(
    connect_as: Connect, ros_node: Any, topic: str
) -> None:
    """A viewer's call_service fails (status and service_response) and the ROS service never runs."""
    seen: list[bool] = []
    lock = threading.Lock()

    def serve(req: Any, resp: Any) -> Any:
        with lock:
            seen.append(req.data)
        resp.success = True
        return resp

    ros_node.create_service(SetBool, topic, serve)
    viewer = await connect_as("viewer")
    await viewer.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                       "args": {"data": False}, "id": "c1"})
    await _forbidden(viewer, "c1", "viewer", "call_service", topic)
    reply = await viewer.expect(op="service_response", id="c1")
    assert reply["result"] is False and "forbidden" in reply["values"]
    admin = await connect_as("admin")
    await admin.send({"op": "call_service", "service": topic, "type": "std_srvs/srv/SetBool",
                      "args": {"data": True}, "id": "c2", "timeout": 30})
    assert (await admin.expect(op="service_response", id="c2"))["result"] is True
    assert seen == [True]


async def test_each_capability_is_denied_without_it(
    connect_as: Connect, auth_bridge: BridgeProcess, ros_node: Any, topic: str
) -> None:
    """Subscribe, advertise_service, action goals, serving actions and params each need their
    grant; the bridge's node makes none of the ROS entities they would need."""
    nobody = await connect_as("nothing")
    await nobody.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String",
                       "id": "s"})
    await _forbidden(nobody, "s", "nothing", "subscribe", topic)
    viewer = await connect_as("viewer")
    await viewer.send({"op": "advertise_service", "service": topic,
                       "type": "std_srvs/srv/SetBool", "id": "as"})
    await _forbidden(viewer, "as", "viewer", "serve_service", topic)
    await viewer.send({"op": "send_action_goal", "action": topic,
                       "action_type": "test_msgs/action/Fibonacci", "args": {"order": 3},
                       "id": "goal"})
    await _forbidden(viewer, "goal", "viewer", "send_action_goal", topic)
    result = await viewer.expect(op="action_result", id="goal")
    assert result["result"] is False
    await viewer.send({"op": "advertise_action", "action": topic,
                       "type": "test_msgs/action/Fibonacci", "id": "aa"})
    await _forbidden(viewer, "aa", "viewer", "serve_action", topic)
    await viewer.send({"op": "call_service", "service": "/rosapi/get_param", "id": "p",
                       "args": {"name": "/some_node:speed"}})
    await _forbidden(viewer, "p", "viewer", "params", "/some_node:speed")
    await nobody.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
    await _forbidden(nobody, "t", "nothing", "introspection", "any name")
    admin = await connect_as("admin")
    made = await bridge_entities(ros_node, auth_bridge, admin, topic + "_marker")
    assert topic not in made["subscriptions"]
    assert topic not in made["services"]  # advertise_service
    assert topic + "/_action/send_goal" not in made["clients"]  # send_action_goal
    assert topic + "/_action/send_goal" not in made["services"]  # advertise_action
    assert "/some_node/get_parameters" not in made["clients"]  # rosapi get_param


async def test_forbidden_ops_in_fragments_cbor_and_rosapi_params(
    connect_as: Connect, auth_bridge: BridgeProcess, ros_node: Any, topic: str
) -> None:
    """A publish split into fragments, an advertise as a CBOR frame and set_param are each
    refused: the bridge's node makes no publisher on the topic and no parameter client for
    the node, whose parameter keeps its value."""
    import cbor2

    from rosbridge_core.protocol.frames import split_fragments

    ros_node.declare_parameter("speed", 1.0)
    node = ros_node.get_fully_qualified_name()
    viewer = await connect_as("viewer")
    text = json.dumps({"op": "publish", "topic": topic, "msg": {"data": "x" * 300}, "id": "fr"})
    for piece in split_fragments(text, 100, "frag"):
        await viewer.send_raw(piece)
    await _forbidden(viewer, "fr", "viewer", "publish", topic)
    await viewer.send_raw(cbor2.dumps({"op": "advertise", "topic": topic,
                                       "type": "std_msgs/msg/String", "id": "cb"}))
    await _forbidden(viewer, "cb", "viewer", "publish", topic)
    await viewer.send({"op": "call_service", "service": "rosapi/set_param", "id": "sp",
                       "args": [f"{node}:speed", "9.0"]})
    await _forbidden(viewer, "sp", "viewer", "params", f"{node}:speed")
    admin = await connect_as("admin")
    made = await bridge_entities(ros_node, auth_bridge, admin, topic + "_marker")
    assert topic not in made["publishers"]
    assert node + "/set_parameters" not in made["clients"]
    assert ros_node.get_parameter("speed").value == 1.0


async def test_deny_wins_over_allow(connect_as: Connect, topic: str) -> None:
    """The tester may publish on /op/* but not on /op/forbidden, which its role denies."""
    operator = await connect_as("tester")
    await operator.send({"op": "advertise", "topic": "/op/forbidden",
                         "type": "std_msgs/msg/String", "id": "no"})
    await _forbidden(operator, "no", "tester", "publish", "/op/forbidden")
    await operator.send({"op": "advertise", "topic": "/op" + topic,
                         "type": "std_msgs/msg/String", "id": "yes"})
    await roundtrip(operator)
    assert not any(op.get("id") == "yes" for op in operator.backlog)


async def test_introspection_lists_only_what_the_role_may_see(
    connect_as: Connect, ros_node: Any, topic: str
) -> None:
    """rosapi topics, services and nodes answers hold only names the role's patterns match."""
    seen, hidden = "/seen" + topic.replace("/", "_"), "/hidden" + topic.replace("/", "_")
    ros_node.create_publisher(String, seen, 10)
    ros_node.create_publisher(String, hidden, 10)
    ros_node.create_service(SetBool, seen + "_srv", lambda q, r: r)
    ros_node.create_service(SetBool, hidden + "_srv", lambda q, r: r)
    admin = await connect_as("admin")
    n = 0

    async def ask(ws: Any, service: str) -> dict[str, Any]:
        nonlocal n
        n += 1
        await ws.send({"op": "call_service", "service": service, "id": f"q{n}"})
        reply = await ws.expect(op="service_response", id=f"q{n}")
        values: dict[str, Any] = reply["values"]
        return values

    async def admin_sees_all() -> bool:
        topics = (await ask(admin, "/rosapi/topics"))["topics"]
        services = (await ask(admin, "/rosapi/services"))["services"]
        return {seen, hidden} <= set(topics) and {seen + "_srv", hidden + "_srv"} <= set(services)

    for _ in range(200):  # graph discovery has no event: poll, as tests.helpers does
        if await admin_sees_all():
            break
        await asyncio.sleep(0.1)
    else:
        raise AssertionError("the graph never listed the test topics")
    narrow = await connect_as("narrow")
    topics = await ask(narrow, "/rosapi/topics")
    assert seen in topics["topics"] and hidden not in topics["topics"]
    assert len(topics["types"]) == len(topics["topics"])
    services = (await ask(narrow, "/rosapi/services"))["services"]
    assert seen + "_srv" in services and hidden + "_srv" not in services
    nodes = (await ask(narrow, "/rosapi/nodes"))["nodes"]
    assert all(node.startswith("/seen") for node in nodes)
    await narrow.send({"op": "call_service", "service": "/rosapi/topic_type", "id": "tt",
                       "args": {"topic": hidden}})
    await _forbidden(narrow, "tt", "narrow", "introspection", hidden)


async def test_first_owner_keeps_a_service_unless_the_role_takes_over(
    connect_as: Connect, topic: str
) -> None:
    """Another principal cannot take a served name; the same principal or take_over can."""
    first = await connect_as("server")
    await first.send({"op": "advertise_service", "service": topic, "type": "std_srvs/srv/SetBool"})
    await roundtrip(first)
    other = await connect_as("server_b")
    await other.send({"op": "advertise_service", "service": topic,
                      "type": "std_srvs/srv/SetBool", "id": "steal"})
    refused = await other.expect(op="status", id="steal")
    assert refused["level"] == "error" and "already served" in refused["msg"]
    admin = await connect_as("admin")  # admin's role has take_over
    await admin.send({"op": "advertise_service", "service": topic,
                      "type": "std_srvs/srv/SetBool", "id": "take"})
    note = await first.expect(op="status", level="warning")
    assert "taken over" in note["msg"] and topic in note["msg"]


def test_role_patterns_and_all() -> None:
    """Globs match whole names, 'all' grants every capability, deny beats allow."""
    role = Role.from_table("r", {"all": ["/robot/*"], "deny": {"publish": ["/robot/estop"]}})
    assert role.allows("subscribe", "/robot/camera") and role.allows("take_over", "/robot/x")
    assert not role.allows("subscribe", "/other")
    assert not role.allows("publish", "/robot/estop") and role.allows("publish", "/robot/cmd")


def test_a_role_limited_to_robots() -> None:
    """'robots' globs say which robots a relay lets the role reach; without it, all."""
    lab = Role.from_table("lab", {"subscribe": ["*"], "robots": ["lab-*", "robot1"]})
    assert lab.reaches("robot1") and lab.reaches("lab-7")
    assert not lab.reaches("robot2") and not lab.reaches("robot10")
    assert Role.from_table("any", {"subscribe": ["*"]}).reaches("robot2")
    assert not Role.from_table("none", {"robots": []}).reaches("robot1")
    with pytest.raises(RoleError, match="role bad: robots must be a list of robot name patterns"):
        Role.from_table("bad", {"robots": "robot1"})


_SEEN_HIDDEN: dict[str, dict[str, Any]] = {
    "/rosapi/topics": {"topics": ["/seen", "/hidden"], "types": ["a/msg/A", "b/msg/B"]},
    "/rosapi/topics_and_raw_types": {"topics": ["/seen", "/hidden"], "types": ["a", "b"],
                                     "typedefs_full_text": ["ta", "tb"]},
    "/rosapi/topics_for_type": {"topics": ["/seen", "/hidden"]},
    "/rosapi/services": {"services": ["/seen", "/hidden"]},
    "/rosapi/services_for_type": {"services": ["/seen", "/hidden"]},
    "/rosapi/nodes": {"nodes": ["/seen", "/hidden"]},
    "/rosapi/publishers": {"publishers": ["/seen", "/hidden"]},
    "/rosapi/subscribers": {"subscribers": ["/seen", "/hidden"]},
    "/rosapi/publishers_qos": {"publishers": ["/seen", "/hidden"],
                               "qos": [{"durability": "volatile"}, {"durability": "volatile"}]},
    "/rosapi/action_servers": {"action_servers": ["/seen", "/hidden"]},
    "/rosapi/node_details": {"subscribing": ["/seen", "/hidden"],
                             "publishing": ["/seen", "/hidden"], "services": ["/seen", "/hidden"]},
    "/rosapi/service_node": {"node": "/hidden"},
}
"""An answer of each rosapi service that names things, holding a visible and a hidden name."""


def test_every_rosapi_answer_naming_things_is_filtered() -> None:
    """Each rosapi list (and service_node) keeps only names the role's introspection matches."""
    from rosbridge_core.security.permissions import filter_rosapi
    from rosbridge_core.session import rosapi

    role = Role.from_table("r", {"introspection": ["/seen*"], "params": ["/seen*"]})
    for service, answer in _SEEN_HIDDEN.items():
        shown = filter_rosapi(role, service, answer)
        for key, column in shown.items():
            assert "/hidden" not in column, (service, key)
            if isinstance(column, list):
                assert len(column) == 1, (service, key)
    names = filter_rosapi(role, "/rosapi/get_param_names", {"names": ["/seen:a", "/hidden:b"]})
    assert names == {"names": ["/seen:a"]}
    # A new rosapi service must be classified here: it names things (above) or it does not.
    naming_nothing = {"action_feedback_details", "action_goal_details", "action_result_details",
                      "get_ros_version", "get_time", "message_details", "service_request_details",
                      "service_response_details", "service_type", "topic_type", "action_type",
                      "get_param", "has_param", "set_param", "delete_param", "get_param_names",
                      "interface_definition", "interfaces"}
    every = set(rosapi.HANDLERS) | set(rosapi.ASYNC_HANDLERS)
    assert every == set(_SEEN_HIDDEN) | {"/rosapi/" + n for n in naming_nothing} | set(MAY)


def test_may_answers_what_the_gate_lets_through() -> None:
    """/rosapi/may_* keep the names the role may use with that capability, as the gate checks
    them (an action's internals and a node's parameter services by what governs them)."""
    from rosbridge_core.security.permissions import filter_rosapi

    role = Role.from_table("r", {"publish": ["/cmd*"], "call_service": ["*"],
                                 "send_action_goal": ["/fib"], "params": ["/n:*"]})
    asked = {"names": ["/cmd_vel", "/other", "/n/set_parameters", "/m/set_parameters",
                       "/fib/_action/send_goal", "/fib", "/n:x"]}
    kept = {MAY[s]: filter_rosapi(role, s, asked)["names"] for s in MAY}
    assert kept == {"publish": ["/cmd_vel"],
                    "call_service": ["/cmd_vel", "/other", "/n/set_parameters",
                                     "/fib/_action/send_goal", "/fib", "/n:x"],
                    "send_action_goal": ["/fib"],
                    "params": ["/n:x"]}
    # asking needs the capability on some name (a role without it is refused at once)
    from rosbridge_core.security.permissions import rosapi_requirement
    assert rosapi_requirement("/rosapi/may_publish", asked) == ("publish", "*")


async def test_a_vanished_owner_loses_its_service(
    ws_connect: Any, bridge: BridgeProcess, topic: str
) -> None:
    """An owner that no longer answers pings (a network drop) gives the name to a new client."""
    owner = await ws_connect()
    await owner.send({"op": "advertise_service", "service": topic, "type": "std_srvs/srv/SetBool"})
    await roundtrip(owner)
    owner.ws.transport.pause_reading()  # like a peer gone without a FIN: no pong comes back
    start = len(bridge.lines)
    newcomer = await ws_connect()
    await newcomer.send({"op": "advertise_service", "service": topic,
                         "type": "std_srvs/srv/SetBool", "id": "mine"})
    await asyncio.to_thread(bridge.wait_for_line, f"serves {topic} but did not answer a ping",
                            10, start)
    caller = await ws_connect()  # a call between clients goes by the bridge's owner table
    await caller.send({"op": "call_service", "service": topic, "args": {"data": True},
                       "type": "std_srvs/srv/SetBool", "id": "c", "timeout": 10})
    request = await newcomer.expect(op="call_service", service=topic)
    await newcomer.send({"op": "service_response", "service": topic, "id": request["id"],
                         "result": True, "values": {"success": True, "message": "newcomer"}})
    reply = await caller.expect(op="service_response", id="c")
    assert reply["values"] == {"success": True, "message": "newcomer"}
    assert not [op for op in newcomer.backlog if op.get("id") == "mine"]
    owner.ws.transport.resume_reading()
