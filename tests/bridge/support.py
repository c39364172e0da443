"""Small helpers for the bridge's integration tests: rclpy callbacks into asyncio."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from tests.helpers import async_wait_until, rosapi_until, send_until_heard


class Inbox:
    """Collects values pushed from rclpy threads; ``get`` awaits the next one."""

    def __init__(self) -> None:
        self.loop = asyncio.get_running_loop()
        self.queue: asyncio.Queue[Any] = asyncio.Queue()

    def __call__(self, value: Any) -> None:
        """Push one value (from any thread)."""
        self.loop.call_soon_threadsafe(self.queue.put_nowait, value)

    async def get(self, timeout: float = 10.0) -> Any:
        """The next value, waiting at most ``timeout`` seconds."""
        return await asyncio.wait_for(self.queue.get(), timeout)


_ANYTHING: Any = object()


async def until_heard(
    send: Callable[[], Any], inbox: Inbox, want: Any = _ANYTHING, timeout: float = 20.0
) -> Any:
    """Call ``send`` (a coroutine function or not) every 0.25 s until ``inbox`` yields ``want``
    (or anything, when no ``want`` is given); returns the value heard
    (:func:`~tests.op_peer.send_until_heard`, whose text says why)."""

    async def listen(wait: float) -> Any:
        heard = await inbox.get(wait)
        while want is not _ANYTHING and heard != want:
            heard = await inbox.get(wait)
        return heard

    return await send_until_heard(
        send, listen, "anything" if want is _ANYTHING else repr(want), timeout=timeout)


async def publish_until_heard(
    ws: Any, topic: str, msg: dict[str, Any], inbox: Inbox, timeout: float = 10.0
) -> Any:
    """Publish ``msg`` through the wire client ``ws`` until ``inbox`` gets a value; returns it."""
    return await until_heard(
        lambda: ws.send({"op": "publish", "topic": topic, "msg": msg}), inbox, timeout=timeout
    )


async def ros_future(future: Any, timeout: float = 10.0) -> Any:
    """Await an rclpy future (completed on an executor thread) from asyncio."""
    loop = asyncio.get_running_loop()
    done: asyncio.Future[Any] = loop.create_future()

    def settle(f: Any) -> None:
        def set_it() -> None:
            if not done.done():
                exc = f.exception()
                if exc is not None:
                    done.set_exception(exc)
                else:
                    done.set_result(f.result())

        loop.call_soon_threadsafe(set_it)

    future.add_done_callback(settle)
    return await asyncio.wait_for(done, timeout)


async def wait_subscribers(pub: Any, n: int = 1, timeout: float = 10.0) -> None:
    """Wait until an rclpy publisher is matched by at least ``n`` subscriptions."""
    await async_wait_until(
        lambda: pub.get_subscription_count() >= n, timeout, f"{n} subscriber(s) on {pub.topic}"
    )


async def wait_publishers(sub: Any, n: int = 1, timeout: float = 10.0) -> None:
    """Wait until an rclpy subscription is matched by at least ``n`` publishers."""
    await async_wait_until(
        lambda: sub.get_publisher_count() >= n, timeout, f"{n} publisher(s) on {sub.topic_name}"
    )


async def wait_service(client: Any, timeout: float = 10.0) -> None:
    """Wait until an rclpy client sees its service."""
    await async_wait_until(client.service_is_ready, timeout, f"service {client.srv_name}")


async def bridge_sees_topic(ws: Any, topic: str, timeout: float = 10.0) -> str:
    """Poll ``/rosapi/topic_type`` until the bridge's graph lists ``topic``; returns its type."""
    found = await rosapi_until(ws, "/rosapi/topic_type", {"topic": topic},
                               lambda v: v["type"], timeout)
    return str(found["type"])


def serve_mult(ros_node: Any, name: str) -> Any:
    """An rclpy ``mult_msgs/srv/MultFloats`` server named ``name`` on ``ros_node`` (it
    answers x * y)."""
    from mult_msgs.srv import MultFloats

    def handle(request: Any, response: Any) -> Any:
        response.result = request.x * request.y
        return response

    return ros_node.create_service(MultFloats, name, handle)


async def serve_set_bool(ws: Any, ros_node: Any, name: str) -> Any:
    """Have the client ``ws`` serve ``std_srvs/SetBool`` as ``name``; an rclpy client of it
    that sees it."""
    from std_srvs.srv import SetBool

    await ws.send({"op": "advertise_service", "service": name, "type": "std_srvs/srv/SetBool"})
    client = ros_node.create_client(SetBool, name)
    await wait_service(client)
    return client
