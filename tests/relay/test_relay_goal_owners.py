"""A relay acts on its own goals only (issue 38, item 3).

Two relays on one Zenoh router (the first is the router, the second its client) serve one
robot (a real rclpy bridge and its exporter); a client of each, with no auth file (so no
role limits them on their relays). The second relay's client finds the first's goal on the
action's status topic and tries both ways a plain call of ``cancel_goal`` reaches it: its id,
and a zero id (every goal). The robot refuses each, naming the relay that sent the goal, and
the goal goes on and succeeds.
"""

from __future__ import annotations

import threading
from typing import Any

import pytest
from test_msgs.action import Fibonacci

from tests.bridge.action_support import FIB, FibServer
from tests.helpers import open_wire
from tests.relay.support import ROBOT, robot_reachable, start_relay, tier, until
from tests.security.test_cancel_goals import _cancel_raw, _new_goal

pytestmark = pytest.mark.timeout(90)


class _HeldServer(FibServer):
    """A Fibonacci server whose goals send feedback until ``release`` is set, then succeed
    (a cancel request is recorded and honoured)."""

    def __init__(self, node: Any, name: str) -> None:
        self.release = threading.Event()
        super().__init__(node, name)

    def _execute(self, handle: Any) -> Any:
        sequence = [0, 1]
        while not self.release.wait(0.05):
            if handle.is_cancel_requested:
                handle.canceled()
                return Fibonacci.Result(sequence=sequence)
            handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        handle.succeed()
        return Fibonacci.Result(sequence=sequence)


async def test_a_relays_client_cannot_cancel_another_relays_goal(ros_node: Any, topic: str
                                                                  ) -> None:
    """The second relay's client cannot cancel the first relay's goal, by its id or a zero
    id: each call is refused naming the relay that sent the goal; the goal was never asked
    to cancel and succeeds for the first relay's client."""
    server = _HeldServer(ros_node, topic)
    try:
        async with tier() as t:
            second = await start_relay(router=t.router, relay_id="relay2")
            try:
                await robot_reachable(second)
                first_id = t.relay.relay_id
                alice = await open_wire(t.url())
                bob = await open_wire(f"ws://127.0.0.1:{second.port}/{ROBOT}")
                graph = t.relay.robots[ROBOT].graph
                await until(lambda: graph.server_types(topic + "/_action/send_goal"),
                            "the first relay to list the action server")
                await bob.send({"op": "subscribe", "topic": topic + "/_action/status",
                                "type": "action_msgs/msg/GoalStatusArray"})
                await alice.send({"op": "send_action_goal", "action": topic,
                                  "action_type": FIB, "args": {"order": 2}, "feedback": True,
                                  "id": "a1"})
                await alice.expect(op="action_feedback", id="a1", timeout=20)
                uuid = await _new_goal(bob, topic, set())

                reply = await _cancel_raw(bob, topic, uuid, "by_id")
                assert reply["result"] is False, reply
                assert f"goal {uuid.hex()} of {topic} was sent through relay {first_id}: " \
                    "relay relay2 may not cancel it (a relay acts on its own goals only)" in \
                    reply["values"], reply
                reply = await _cancel_raw(bob, topic, bytes(16), "every")
                assert reply["result"] is False, reply
                assert f"relay relay2 may not cancel every goal of {topic}: a zero goal id or " \
                    f"a stamp would cancel goals relay {first_id} sent" in reply["values"], reply
                assert not server.cancel_requests.is_set()
                server.release.set()
                result = await alice.expect(op="action_result", id="a1", timeout=20)
                assert result["status"] == 4 and result["result"] is True, result
                await alice.close()
                await bob.close()
            finally:
                await second.close()
    finally:
        server.release.set()
        server.destroy()
