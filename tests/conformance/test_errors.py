"""Every mistake fails the same way on MockRos and on the real client with the real bridge.

Each case of issue 13 is one test here, run against both backends (the ``ros``
fixture): what is known locally raises at the call, what only the bridge knows
raises at ``await`` or reaches the error hook, and the texts say how to fix it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from typing import Any

import pytest

import roslibpy_lite
from msgs.mult_msgs.srv import MultFloats
from msgs.std_msgs.msg import Int32, String
from roslibpy_lite import (
    InvalidMessageError,
    MockRos,
    Ros,
    RosFront,
    RosLibError,
    ServiceError,
    StatusError,
    UsageError,
)
from tests.conformance.test_conformance import heard

MULT = "mult_msgs/srv/MultFloats"


@pytest.fixture(params=["mock", "bridge"])
async def loose(request: pytest.FixtureRequest) -> AsyncIterator[RosFront]:
    """A backend made with ``validate=False``: dicts reach the bridge unchecked."""
    if request.param == "mock":
        async with MockRos(validate=False) as mock:
            yield mock
        return
    bridge = request.getfixturevalue("bridge")
    async with roslibpy_lite.connect(bridge.url, validate=False) as client:
        yield client


def _errors(ros: Any) -> asyncio.Queue[RosLibError]:
    """A queue fed by the backend's error hook."""
    queue: asyncio.Queue[RosLibError] = asyncio.Queue()
    ros.on_error(queue.put_nowait)
    return queue


# -- what is known locally raises at the call -----------------------------------------------------

async def test_type_typo_says_did_you_mean(ros: Ros, topic: str) -> None:
    """A misspelt type raises UsageError at the call, with the close names, for every request."""
    for call in (
        lambda: ros.advertise(topic, "std_msgs/msg/Strin"),
        lambda: ros.subscribe(topic, "std_msgs/msg/Strin", callback=print),
        lambda: ros.subscribe(topic, "std_msgs/Strin"),
    ):
        with pytest.raises(UsageError, match="did you mean 'std_msgs/msg/String'"):
            call()
    with pytest.raises(UsageError, match="did you mean 'mult_msgs/srv/MultFloats'"):
        ros.call_service(topic, "mult_msgs/srv/MultFloat", {})
    with pytest.raises(UsageError, match="did you mean 'mult_msgs/srv/MultFloats'"):
        ros.advertise_service(topic, "mult_msgs/MultFloat", lambda req: None)


async def test_a_class_of_the_wrong_kind_is_named(ros: Ros, topic: str) -> None:
    """A message class where a service is needed (and the reverse) names both kinds."""
    with pytest.raises(UsageError, match="is a message type, but a service type is needed"):
        ros.call_service(topic, String, {})  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="is a service type, but a message type is needed"):
        ros.advertise(topic, MultFloats)  # type: ignore[type-var]


async def test_a_dict_that_does_not_fit_raises_at_publish(ros: Ros, topic: str) -> None:
    """A dict with a field the type lacks, or a value of the wrong kind, raises at publish."""
    by_name = await ros.advertise(topic, "std_msgs/msg/Int32")
    typed = await ros.advertise(topic, Int32)
    for pub in (by_name, typed):
        with pytest.raises(InvalidMessageError, match="nope") as lacks:
            await pub.publish({"nope": 1})
        assert "a field of std_msgs/msg/Int32 (data)" in str(lacks.value)
        with pytest.raises(InvalidMessageError, match="data") as kind:
            await pub.publish({"data": "seven"})
        assert kind.value.path == "data"


async def test_call_arguments_are_checked_at_the_call(ros: Ros, topic: str) -> None:
    """Request fields that do not fit raise InvalidMessageError before anything is sent."""
    with pytest.raises(InvalidMessageError, match="x"):
        ros.call_service(topic, MULT, {"x": "two"})


# -- a forgotten await --------------------------------------------------------------------------

async def test_call_result_used_without_await_says_so(
    ros: Ros, topic: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Indexing an un-awaited call_service raises 'did you forget await?'; dropping it logs it."""
    async with ros.advertise_service(topic, MULT, lambda req: {"result": 1.0}):
        pending = ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0})
        with pytest.raises(UsageError, match="did you forget await"):
            pending["result"]
        with pytest.raises(UsageError, match="did you forget await"):
            pending.result  # noqa: B018
        with caplog.at_level(logging.ERROR, "roslibpy_lite.client"):
            del pending
        assert "never awaited: did you forget await?" in caplog.text
        assert await ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0}, timeout=15) == {
            "result": 1.0
        }


async def test_publish_without_await_still_sends(ros: Ros, topic: str) -> None:
    """A publish whose await was forgotten is sent anyway (the message goes out at the call)."""
    pub = await ros.advertise(topic, "std_msgs/msg/Int32")
    async with ros.subscribe(topic, "std_msgs/msg/Int32") as sub:
        await heard(pub, sub, {"data": -1})
        while sub.pending:
            await sub.get(1)
        pub.publish({"data": 42})  # type: ignore[unused-coroutine]  # the mistake under test
        while (await sub.get(10))["data"] != 42:
            pass


# -- what only the bridge knows ------------------------------------------------------------------

async def test_refused_subscribe_raises_at_await(ros: Ros, topic: str) -> None:
    """Subscribing with another type than the graph's raises StatusError at await, with a callback too."""
    await ros.advertise(topic, "std_msgs/msg/String")
    with pytest.raises(StatusError, match="std_msgs/msg/String"):
        await ros.subscribe(topic, "std_msgs/msg/Int32", callback=print)


async def test_refused_subscribe_not_awaited_reaches_the_error_hook(
    ros: Ros, topic: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Without await, the refusal goes to on_error and the log, and the handle carries it."""
    errors = _errors(ros)
    await ros.advertise(topic, "std_msgs/msg/String")
    with caplog.at_level(logging.WARNING, "roslibpy_lite.client"):
        sub = ros.subscribe(topic, "std_msgs/msg/Int32", callback=print)
        error = await asyncio.wait_for(errors.get(), 15)
    assert isinstance(error, StatusError) and "std_msgs/msg/String" in str(error)
    assert sub.error is error
    assert f"bridge refused {sub.id}" in caplog.text


async def test_bridge_publish_error_reaches_hook_and_next_publish(
    loose: RosFront, topic: str
) -> None:
    """A dict the bridge cannot convert (unchecked locally) goes to on_error and is in
    pub.last_error at once; the next publish raises it."""
    errors = _errors(loose)
    pub = await loose.advertise(topic, "std_msgs/msg/Int32")
    await pub.publish({"data": "seven"})
    error = await asyncio.wait_for(errors.get(), 15)
    assert isinstance(error, StatusError)
    assert f"publish to {topic}" in str(error) and "data" in str(error)
    assert pub.last_error is error and pub.error is None  # the publisher itself still works
    with pytest.raises(StatusError, match="data"):
        await pub.publish({"data": 7})
    await pub.publish({"data": 8})  # raised once; the publisher goes on


async def test_missing_service_fails_with_the_bridge_reason(ros: Ros, topic: str) -> None:
    """A call to a service nobody serves fails with 'does not exist', long before its timeout."""
    with pytest.raises(ServiceError, match="does not exist") as failed:
        await ros.call_service(topic + "_nobody", MULT, {"x": 1.0, "y": 1.0}, timeout=30)
    assert str(failed.value).startswith(f"service {topic}_nobody does not exist")


async def test_handler_failure_reason_appears_once(
    ros: Ros, topic: str, caplog: pytest.LogCaptureFixture
) -> None:
    """The caller sees the handler's reason once; the server logs the class and message."""

    def handler(req: Any) -> Any:
        raise ZeroDivisionError("y must not be zero")

    async with ros.advertise_service(topic, MULT, handler):
        with caplog.at_level(logging.WARNING, "roslibpy_lite.client"), \
                pytest.raises(ServiceError) as failed:
            await ros.call_service(topic, MULT, {"x": 1.0, "y": 0.0}, timeout=15)
    assert str(failed.value) == f"service {topic} failed: y must not be zero"
    assert failed.value.reason == "y must not be zero"
    assert f"handler of {topic} raised ZeroDivisionError: y must not be zero" in caplog.text


async def test_bulky_dicts_are_checked_by_shape(ros: Ros, topic: str) -> None:
    """An image dict's field names and kinds are checked; its pixel data is left to the bridge."""
    import base64

    pub = await ros.advertise(topic, "sensor_msgs/msg/Image")
    image = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}, "is_bigendian": 0,
             "height": 480, "width": 640, "encoding": "rgb8", "step": 1920,
             "data": base64.b64encode(bytes(640 * 480 * 3)).decode()}
    await pub.publish(image)
    with pytest.raises(InvalidMessageError, match="width"):
        await pub.publish({**image, "width": "640"})
    with pytest.raises(InvalidMessageError, match="data"):
        await pub.publish({**image, "data": 7})
