"""Through the bridge a client cancels only the goals it sent, unless its role has
``cancel_any_goal`` (issue 27, item 12).

A real rclpy action server records which goals it was asked to cancel; three clients with
tokens (two whose role may send goals, one whose role may also cancel any goal) try both
ways a client can cancel: the ``cancel_action_goal`` op and a plain ``call_service`` to
``<action>/_action/cancel_goal``.
"""

from __future__ import annotations

import base64
import threading
from pathlib import Path
from typing import Any

from rosbridge_core.security.auth import hash_token, load_auth_file, new_token
from tests.bridge.action_support import FibServer, bridge_sees_action, send_goal
from tests.helpers import ROOT, WireClient
from tests.security.support import wire

ROLES = """
[roles.goals]
introspection = ["*"]
send_action_goal = ["*"]

[roles.goals_any]
introspection = ["*"]
send_action_goal = ["*"]
cancel_any_goal = ["*"]
"""
CANCEL_TYPE = "action_msgs/srv/CancelGoal"
CANCELED = 5


class _RecordingServer(FibServer):
    """A slow Fibonacci server that records the id of each goal it is asked to cancel."""

    def __init__(self, node: Any, name: str) -> None:
        self.canceled: list[bytes] = []
        self._lock = threading.Lock()
        super().__init__(node, name, slow=True)

    def _cancel(self, handle: Any) -> Any:
        with self._lock:
            self.canceled.append(bytes(handle.goal_id.uuid))
        return super()._cancel(handle)


def _auth_file(tmp: Path) -> dict[str, str]:
    """Write an auth file: alice and bob may send goals, carol may also cancel any goal."""
    text, tokens = ROLES, {}
    for name, role in (("alice", "goals"), ("bob", "goals"), ("carol", "goals_any")):
        tokens[name] = token = new_token()
        text += f'\n[principals.{name}]\nrole = "{role}"\ntoken_hash = "{hash_token(token)}"\n'
    (tmp / "auth.toml").write_text(text)
    return tokens


async def _cancel_raw(ws: WireClient, action: str, uuid: bytes, id: str,
                      sec: int = 0) -> dict[str, Any]:
    """Call the action's cancel_goal service as a plain service; its service_response."""
    args = {"goal_info": {"goal_id": {"uuid": list(uuid)}, "stamp": {"sec": sec, "nanosec": 0}}}
    await ws.send({"op": "call_service", "service": action + "/_action/cancel_goal",
                   "type": CANCEL_TYPE, "args": args, "id": id, "timeout": 30})
    reply: dict[str, Any] = await ws.expect(op="service_response", id=id, timeout=40)
    return reply


def _uuid(goal_info: dict[str, Any]) -> bytes:
    raw = goal_info["goal_id"]["uuid"]
    return base64.b64decode(raw) if isinstance(raw, str) else bytes(raw)


async def _new_goal(ws: WireClient, action: str, known: set[bytes]) -> bytes:
    """The id of a goal the action's status topic lists that is not in ``known``."""
    while True:
        msg = await ws.expect(op="publish", topic=action + "/_action/status", timeout=20)
        fresh = {_uuid(s["goal_info"]) for s in msg["msg"]["status_list"]} - known
        if fresh:
            (uuid,) = fresh
            return uuid


async def test_a_client_cancels_only_its_own_goals_unless_granted_cancel_any_goal(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """Bob (send_action_goal only) cannot cancel alice's goal: not with a zero goal id, not
    with a stamp, not with her goal's id, not with the op; his own goal he can. Carol
    (cancel_any_goal) cancels every goal with a zero id, alice's included."""
    tokens = _auth_file(tmp_path)
    bridge = make_bridge("--auth-file", str(tmp_path / "auth.toml"))
    action = topic + "_act"
    server = _RecordingServer(ros_node, action)
    alice, bob, carol = [await wire(bridge.url, tokens[n]) for n in ("alice", "bob", "carol")]
    try:
        await bridge_sees_action(alice, action)
        # Bob watches the action's status topic (send_action_goal allows it): every goal id.
        await bob.send({"op": "subscribe", "topic": action + "/_action/status",
                        "type": "action_msgs/msg/GoalStatusArray"})
        await send_goal(alice, action, {"order": 5}, "a1", feedback=True)
        await alice.expect(op="action_feedback", id="a1", timeout=20)
        alices = await _new_goal(bob, action, set())

        # Each way bob can try is refused with a text that says why, and reaches no server.
        for uuid, sec, id, words in (
            (bytes(16), 0, "zero", ("forbidden", "goals", "zero goal id", "cancel_any_goal")),
            (alices, 1, "stamp", ("forbidden", "zero goal id or a stamp")),
            (alices, 0, "hers", ("forbidden", alices.hex(), "did not send it")),
        ):
            reply = await _cancel_raw(bob, action, uuid, id, sec)
            assert reply["result"] is False, reply
            assert all(w in reply["values"] for w in words), reply["values"]
            assert "role goals" in reply["values"] and action in reply["values"]
        await bob.send({"op": "cancel_action_goal", "action": action, "id": "a1"})
        status = await bob.expect(op="status", id="a1")
        assert status["level"] == "error" and "no goal 'a1'" in status["msg"], status
        # The service answered each call before the bridge answered it: nothing reached it.
        assert server.canceled == []

        # His own goal bob may cancel, by its id, as a plain service.
        await send_goal(bob, action, {"order": 5}, "b1", feedback=True)
        await bob.expect(op="action_feedback", id="b1", timeout=20)
        bobs = await _new_goal(bob, action, {alices})
        reply = await _cancel_raw(bob, action, bobs, "mine")
        assert reply["result"] is True, reply
        assert [_uuid(g) for g in reply["values"]["goals_canceling"]] == [bobs]
        assert (await bob.expect(op="action_result", id="b1", timeout=20))["status"] == CANCELED
        assert server.canceled == [bobs]  # alice's goal was never asked to cancel

        # Carol's role has cancel_any_goal: a zero goal id cancels every goal, alice's too.
        reply = await _cancel_raw(carol, action, bytes(16), "all")
        assert reply["result"] is True, reply
        assert [_uuid(g) for g in reply["values"]["goals_canceling"]] == [alices]
        result = await alice.expect(op="action_result", id="a1", timeout=20)
        assert result["status"] == CANCELED, result
    finally:
        for ws in (alice, bob, carol):
            await ws.ws.close()
        server.destroy()


def test_the_example_auth_file_shows_the_grant() -> None:
    """examples/auth.example.toml has a role with cancel_any_goal, and the operator has not."""
    roles = load_auth_file(ROOT / "examples" / "auth.example.toml").roles
    assert roles["supervisor"].allows("cancel_any_goal", "/navigate_to_pose")
    assert roles["supervisor"].allows("send_action_goal", "/navigate_to_pose")
    assert not roles["operator"].has("cancel_any_goal")
