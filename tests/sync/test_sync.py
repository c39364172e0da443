"""The blocking client does what the asyncio client does, on MockRos and on the real bridge.

These mirror tests/conformance: same operations, same exceptions, without async/await.
"""

from __future__ import annotations

import queue
from typing import Any

import pytest

from msgs.mult_msgs.srv import MultFloats
from msgs.std_msgs.msg import Int32, String
from roslibpy_lite import (
    ConnectionClosed,
    ConnectionState,
    InvalidMessageError,
    RosTimeoutError,
    ServiceError,
    UsageError,
    sync,
)
from tests.sync.support import heard, skip_repeats

MULT = "mult_msgs/srv/MultFloats"
Ros = sync.Client | sync.MockRos


def test_publish_subscribe_round_trip(ros: Ros, topic: str) -> None:
    """Dicts published on a topic arrive at a blocking subscription, in order."""
    pub = ros.advertise(topic, "std_msgs/msg/Int32")
    with ros.subscribe(topic, "std_msgs/msg/Int32") as sub:
        assert heard(pub, sub, {"data": -1}) == {"data": -1}
        for i in range(5):
            pub.publish({"data": i})
        got = [skip_repeats(sub, {"data": -1})["data"]]
        got += [sub.get(10)["data"] for _ in range(4)]
        assert got == [0, 1, 2, 3, 4]
    pub.unadvertise()


def test_iterate_with_timeout(ros: Ros, topic: str) -> None:
    """``for msg in sub.messages(timeout)`` yields messages and raises RosTimeoutError on silence."""
    with ros.advertise(topic, "std_msgs/msg/Int32") as pub, \
            ros.subscribe(topic, "std_msgs/msg/Int32") as sub:
        heard(pub, sub, {"data": 0})
        pub.publish({"data": 1})
        seen = []
        with pytest.raises(RosTimeoutError, match=topic):
            for msg in sub.messages(timeout=1.0):
                seen.append(msg["data"])
        assert seen[-1] == 1


def test_iteration_ends_when_unsubscribed(ros: Ros, topic: str) -> None:
    """A plain ``for`` over a subscription ends once it is unsubscribed."""
    pub = ros.advertise(topic, "std_msgs/msg/Int32")
    sub = ros.subscribe(topic, "std_msgs/msg/Int32")
    heard(pub, sub, {"data": 7})
    sub.unsubscribe()
    assert all(msg == {"data": 7} for msg in sub)
    with pytest.raises(UsageError, match="closed"):
        sub.get(1)


def test_callback_runs_on_the_loop_thread(ros: Ros, topic: str) -> None:
    """A subscription callback gets every message, on the client's loop thread, not the caller's."""
    import threading

    got: queue.Queue[tuple[Any, str]] = queue.Queue()
    pub = ros.advertise(topic, "std_msgs/msg/String")
    probe = ros.subscribe(topic, "std_msgs/msg/String")
    heard(pub, probe, {"data": "probe"})
    probe.close()
    with ros.subscribe(topic, "std_msgs/msg/String",
                       lambda msg: got.put((msg, threading.current_thread().name))):
        pub.publish({"data": "to callback"})
        msg, thread = got.get(timeout=10)
        while msg == {"data": "probe"}:
            msg, thread = got.get(timeout=10)
    assert msg == {"data": "to callback"}
    assert thread.startswith("roslibpy_lite.sync") and thread != threading.current_thread().name


def test_callback_may_publish_but_not_block(ros: Ros, topic: str) -> None:
    """From a callback, publish is queued; a blocking call raises UsageError instead of hanging."""
    errors: queue.Queue[BaseException] = queue.Queue()
    relay = ros.advertise(topic + "_out", "std_msgs/msg/Int32")
    out = ros.subscribe(topic + "_out", "std_msgs/msg/Int32")

    def on_msg(msg: dict[str, Any]) -> None:
        relay.publish({"data": msg["data"] * 10})
        try:
            ros.call_service(topic + "_none", MULT, {})
        except UsageError as exc:
            errors.put(exc)

    pub = ros.advertise(topic, "std_msgs/msg/Int32")
    with ros.subscribe(topic, "std_msgs/msg/Int32", on_msg):
        assert heard(pub, out, {"data": 4}) == {"data": 40}
    assert "callback" in str(errors.get(timeout=5))


def test_typed_messages_round_trip(ros: Ros, topic: str) -> None:
    """Typed publishers and subscriptions exchange instances; bad ones raise the usual errors."""
    with ros.advertise(topic, String) as pub, ros.subscribe(topic, String) as sub:
        first = heard(pub, sub, String(data="typed"))
        assert isinstance(first, String) and first.data == "typed"
    typed = ros.advertise(topic + "_i", Int32)
    with pytest.raises(UsageError, match="std_msgs/msg/Int32"):
        typed.publish(String(data="x"))  # type: ignore[arg-type]
    bad = Int32()
    bad.data = 2**40  # reassigned after it was built (construction would refuse it)
    with pytest.raises(InvalidMessageError, match="data"):
        typed.publish(bad)


def test_latched_topic_reaches_late_subscriber(ros: Ros, topic: str) -> None:
    """A latched topic's last message reaches a subscription made after it was published."""
    pub = ros.advertise(topic, "std_msgs/msg/String", latch=True)
    pub.publish({"data": "the map"})
    with ros.subscribe(topic, "std_msgs/msg/String") as late:
        assert late.get(15) == {"data": "the map"}


def test_service_serve_and_call(ros: Ros, topic: str) -> None:
    """A sync handler serves calls, with dicts and with typed requests and responses."""
    with ros.advertise_service(topic, MULT, lambda req: {"result": req["x"] * req["y"]}):
        assert ros.call_service(topic, MULT, {"x": 2.5, "y": 4.0}, timeout=15) == {"result": 10.0}
        reply = ros.call_service(topic, MultFloats, MultFloats.Request(x=3.0, y=-2.0), timeout=15)
        assert isinstance(reply, MultFloats.Response) and reply.result == -6.0


def test_handler_may_block_and_call_the_client(ros: Ros, topic: str) -> None:
    """A sync handler runs on a worker thread, so it may itself call a service of the client."""
    inner = topic + "_inner"
    with ros.advertise_service(inner, MULT, lambda req: {"result": req["x"] * req["y"]}), \
            ros.advertise_service(topic, MULT, lambda req: ros.call_service(inner, MULT, req,
                                                                            timeout=15)):
        assert ros.call_service(topic, MULT, {"x": 3.0, "y": 3.0}, timeout=30) == {"result": 9.0}


def test_handler_exception_and_unknown_service(ros: Ros, topic: str) -> None:
    """A raising handler and an unknown service both give ServiceError with the reason."""

    def handler(req: Any) -> Any:
        raise ValueError("no multiplying on Sundays")

    with ros.advertise_service(topic, MULT, handler), \
            pytest.raises(ServiceError, match="no multiplying on Sundays"):
        ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0}, timeout=15)
    with pytest.raises(ServiceError, match=topic):
        ros.call_service(topic + "_nobody", MULT, {"x": 1.0, "y": 1.0}, timeout=None)


def test_slow_service_times_out(ros: Ros, topic: str) -> None:
    """A call whose answer does not come in time raises RosTimeoutError."""
    import threading

    release = threading.Event()

    def slow(req: Any) -> Any:
        release.wait(30)
        return {"result": 0.0}

    with ros.advertise_service(topic, MULT, slow):
        with pytest.raises(RosTimeoutError, match=topic):
            ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0}, timeout=1.0)
        release.set()


def test_state_and_closing(ros: Ros, topic: str) -> None:
    """State is CONNECTED, state callbacks see CLOSED, and a closed client refuses calls."""
    seen: list[ConnectionState] = []
    assert ros.is_connected and ros.state is ConnectionState.CONNECTED
    ros.wait_connected(1)
    remove = ros.on_state_change(seen.append)
    ros.close()
    assert seen == [ConnectionState.CLOSED]
    assert not ros.is_connected and ros.state.value == "closed"
    with pytest.raises(ConnectionClosed):
        ros.advertise(topic, "std_msgs/msg/Int32")
    ros.close()  # harmless
    remove()  # so is removing a callback afterwards (no "Event loop is closed")


def test_mock_conveniences() -> None:
    """sync.MockRos plays the robot's side: inject, published, subscribers, served, disconnect."""
    with sync.MockRos() as mock:
        got: list[Any] = []
        mock.subscribe("/in", "std_msgs/msg/Float64", got.append)
        mock.inject("/in", {"data": 1.5})
        assert got == [{"data": 1.5}] and mock.subscribers("/in") == 1
        pub = mock.advertise("/out", "std_msgs/msg/Float64")
        mock.disconnect()
        assert mock.state is ConnectionState.RECONNECTING
        pub.publish({"data": 2.0})
        assert mock.published("/out") == []
        mock.reconnect()
        assert mock.published("/out") == [{"data": 2.0}]
        mock.advertise_service("/s", MULT, lambda req: {"result": 0.0})
        assert mock.served() == ["/s"]
        mock.drain()


def test_many_publishes_keep_their_order(ros: Ros, topic: str) -> None:
    """Publishes handed over without waiting for each still arrive all and in order.

    The ROS publisher's history holds the whole burst (queue_size), as KEEP_LAST
    DDS may overwrite samples a busy subscriber has not acknowledged yet; so does
    the bridge's send queue for this subscription (queue_length: its default of
    100 drops the oldest when the burst outruns the websocket, with a warning).
    """
    pub = ros.advertise(topic, "std_msgs/msg/Int32", queue_size=400)
    with ros.subscribe(topic, "std_msgs/msg/Int32", buffer_size=1000, queue_length=400) as sub:
        heard(pub, sub, {"data": -1})
        for i in range(300):
            pub.publish({"data": i})
        pub.flush()
        first = skip_repeats(sub, {"data": -1})["data"]
        assert [first] + [sub.get(10)["data"] for _ in range(299)] == list(range(300))
    pub.close()
    with pytest.raises(UsageError, match="closed"):
        pub.publish({"data": 1})


def test_blocking_errors_hint_at_blocking_calls() -> None:
    """The blocking client's errors name its own calls (``sub.next(timeout)``,
    ``ros.wait_connected()``), not the asyncio client's ``await ...``."""
    from roslibpy_lite import NoMessageYet, NotConnected

    with sync.MockRos() as mock:
        sub = mock.subscribe("/hint", "std_msgs/msg/Int32")
        with pytest.raises(NoMessageYet, match=r"; sub\.next\(timeout\) waits for one$"):
            sub.latest()
        mock.disconnect()
        with pytest.raises(NotConnected, match=r"ros\.wait_connected\(\) first") as caught:
            sub.collect(0.1)
        assert "await" not in str(caught.value)
