"""What a role sees and reaches over the stock Foxglove client, as over rosbridge."""

from __future__ import annotations

import itertools
import time
from typing import Any

import pytest

from tests.helpers import BridgeProcess
from tests.peers import scenarios
from tests.peers.foxglove.support import (
    DEADLINE,
    _all_sent,
    _as,
    _graph_names,
    _parameter_values,
    _published_by,
    _rosbridge_refusal,
    _update,
    _wait_error,
)
from tests.peers.peer import foxglove_peer

# -- what a role sees and reaches, as over rosbridge ------------------------------------------------


def test_connection_graph_needs_introspection(secured: tuple[BridgeProcess, Any],
                                              ros_node: Any, topic: str) -> None:
    """A role without introspection (it may subscribe to anything) is not offered
    connectionGraph, and its subscribeConnectionGraph is refused in the words rosbridge
    refuses it /rosapi/nodes in: no graph update reaches it; admin's follows the graph."""
    from std_msgs.msg import String

    bridge, auth = secured
    ros_node.create_publisher(String, topic, 10)
    why = "forbidden: role tester may not introspection on any name"
    assert why in _rosbridge_refusal(bridge, auth.tokens["tester"], "/rosapi/nodes")
    tester = _as(secured, "tester")
    try:
        assert "connectionGraph" not in tester.info["serverInfo"]["capabilities"]
        tester.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
        tester.request("subscribe_graph")
        assert f"subscribeConnectionGraph: {why}" in _wait_error(tester, why)
        assert _graph_names(_all_sent(tester)) == set()
    finally:
        tester.close()
    admin = _as(secured, "admin")
    try:
        assert "connectionGraph" in admin.info["serverInfo"]["capabilities"]
        admin.request("subscribe_graph")
        admin.wait_event(_published_by(topic, ros_node.get_fully_qualified_name()), DEADLINE,
                         "a graph update with the topic")
    finally:
        admin.close()


def test_connection_graph_shows_only_what_the_role_sees(secured: tuple[BridgeProcess, Any],
                                                        ros_node: Any, topic: str) -> None:
    """A role with introspection on /seen* only follows a connection graph that names its
    /seen* topics, services and nodes and nothing else (not the /seen node's other topic,
    nor the node subscribing from outside /seen*), as rosapi's lists would."""
    import rclpy
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    seen_node = rclpy.create_node("seen" + topic.replace("/", "_"), context=ros_node.context)
    try:
        seen_id = seen_node.get_fully_qualified_name()
        seen_node.create_publisher(String, "/seen" + topic, 10)
        seen_node.create_publisher(String, topic, 10)
        seen_node.create_service(SetBool, "/seen" + topic + "_srv", lambda req, res: res)
        ros_node.create_subscription(String, "/seen" + topic, lambda msg: None, 10)
        narrow = _as(secured, "narrow")
        try:
            assert "connectionGraph" in narrow.info["serverInfo"]["capabilities"]
            narrow.request("subscribe_graph")
            narrow.wait_event(_published_by("/seen" + topic, seen_id), DEADLINE,
                              "a graph update with the /seen topic")
            narrow.wait_event(lambda e: e.get("event") == "connectionGraphUpdate" and any(
                s["name"] == "/seen" + topic + "_srv" and seen_id in s["providerIds"]
                for s in e["update"]["advertisedServices"]), DEADLINE, "the /seen service")
            names = _graph_names(_all_sent(narrow))
            assert {"/seen" + topic, "/seen" + topic + "_srv", seen_id} <= names
            assert [n for n in names if not n.startswith("/seen")] == []
        finally:
            narrow.close()
    finally:
        seen_node.destroy_node()  # type: ignore[no-untyped-call]


def test_call_the_role_may_not_make_never_runs(secured: tuple[BridgeProcess, Any],
                                               ros_node: Any, topic: str) -> None:
    """A role that may call only /probe/* services calls another service by the id an admin
    connection learnt: a serviceCallFailure says forbidden and the rclpy handler never runs
    (it does for the admin's call)."""
    from std_srvs.srv import SetBool

    calls: list[bool] = []

    def answer(request: Any, response: Any) -> Any:
        calls.append(request.data)
        response.success = True
        return response

    ros_node.create_service(SetBool, topic, answer)
    admin = _as(secured, "admin")
    try:
        service = admin.request("service", service=topic, timeout_ms=int(DEADLINE * 1000))
        prober = _as(secured, "prober")
        try:
            with pytest.raises(Exception, match=f"forbidden: role prober may not call_service "
                                                f"on {topic}"):
                prober.request("call_service_id", service_id=service["id"], hex="0001000001",
                               timeout=DEADLINE)
        finally:
            prober.close()
        assert admin.request("call_service", service=topic, request={"data": False},
                             timeout=DEADLINE)["value"]["success"] is True
        assert calls == [False]  # only the admin's call reached the service
    finally:
        admin.close()


def test_parameter_lists_need_params(secured: tuple[BridgeProcess, Any], ros_node: Any,
                                     topic: str) -> None:
    """A role without params is not offered the parameter capabilities, and its
    getParameters and subscribeParameterUpdates of every parameter are refused in the words
    rosbridge refuses it /rosapi/get_param_names in (the request's id answered with no
    values); a role with params on *_display names gets those names only."""
    bridge, auth = secured
    why = "forbidden: role tester may not params on any name"
    assert why in _rosbridge_refusal(bridge, auth.tokens["tester"], "/rosapi/get_param_names")
    tester = _as(secured, "tester")
    try:
        assert not {"parameters", "parametersSubscribe"} & set(
            tester.info["serverInfo"]["capabilities"])
        assert _parameter_values(tester, "all", "get_parameters", names=[]) == []
        assert f"getParameters: {why}" in _wait_error(tester, "getParameters")
        tester.request("subscribe_parameters", names=[])
        assert f"subscribeParameterUpdates: {why}" in _wait_error(tester,
                                                                  "subscribeParameterUpdates")
    finally:
        tester.close()
    prefix = topic.strip("/").replace("/", "_")
    ros_node.declare_parameter(prefix + "_display", 1.0)
    ros_node.declare_parameter(prefix + "_secret", 2.0)
    node = ros_node.get_fully_qualified_name()
    prober = _as(secured, "prober")
    try:
        assert {"parameters", "parametersSubscribe"} <= set(
            prober.info["serverInfo"]["capabilities"])
        deadline = time.monotonic() + DEADLINE
        for n in itertools.count():  # until the bridge sees the node's parameters
            names = {p["name"] for p in _parameter_values(prober, f"all{n}", "get_parameters",
                                                          names=[])}
            if f"{node}.{prefix}_display" in names:
                break
            assert time.monotonic() < deadline, names
        assert names and all(name.endswith("_display") for name in names), names
    finally:
        prober.close()
        ros_node.undeclare_parameter(prefix + "_display")
        ros_node.undeclare_parameter(prefix + "_secret")


def test_follow_all_parameters(bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """subscribeParameterUpdates with no names follows every parameter: a parameter changed
    in ROS comes as an update, named /node.param."""
    from rclpy.parameter import Parameter

    name = topic.strip("/").replace("/", "_") + "_gain"
    ros_node.declare_parameter(name, 0.0)
    full = f"{ros_node.get_fully_qualified_name()}.{name}"
    peer = foxglove_peer(bridge.url, bridge)
    try:
        peer.request("subscribe_parameters", names=[])
        deadline = time.monotonic() + DEADLINE
        for n in itertools.count(1):  # until the bridge's /parameter_events reader is matched
            ros_node.set_parameters([Parameter(name, value=float(n))])  # type: ignore[no-untyped-call]
            entry = {"name": full, "value": float(n), "type": "float64"}
            try:
                _update(peer, entry, scenarios.ATTEMPT)
                break
            except AssertionError:
                assert time.monotonic() < deadline, f"no update of {full}\n{peer.diagnostics()}"
    finally:
        peer.close()
        ros_node.undeclare_parameter(name)
