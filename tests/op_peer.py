"""A client's end of a rosbridge conversation in the tests: :class:`OpPeer` sends ops and
awaits matching ones (:class:`WireClient` over a websocket; ``tests.session.harness.Client``
over a memory link), and what tests do with one: a round trip, rosapi calls, bad input
with a bystander, sending until heard.

``tests.helpers`` re-exports these names for its importers.
"""

from __future__ import annotations

import asyncio
import inspect
import itertools
import json
import queue
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect

__all__ = [
    "FIB",
    "OpPeer",
    "WireClient",
    "ask_until",
    "error_text",
    "fib",
    "open_wire",
    "rosapi",
    "rosapi_until",
    "roundtrip",
    "send_goal",
    "send_until_heard",
    "send_until_heard_sync",
    "sender_and_bystander",
    "still_working",
]


T = TypeVar("T")


async def send_until_heard(
    send: Callable[[], Any], listen: Callable[[float], Awaitable[T]], what: str,
    attempt: float = 0.25, timeout: float = 20.0,
) -> T:
    """Call ``send`` (a coroutine function or not), then ``listen`` for at most ``attempt``
    seconds, until ``listen`` returns what it heard (it raises TimeoutError or
    AssertionError when nothing came): that is returned. AssertionError naming ``what``
    after ``timeout`` s.

    A ROS subscription can see a new publisher before that publisher sees it (DDS
    matching is not symmetric), and nothing says when discovery is done, so one message
    sent at once may reach nobody; sending again until heard is the way to know the path
    is up. In memory the first is heard.
    """
    deadline = time.monotonic() + timeout
    while True:
        sent = send()
        if inspect.isawaitable(sent):
            await sent
        try:
            return await listen(attempt)
        except (TimeoutError, AssertionError):
            if time.monotonic() >= deadline:
                raise AssertionError(f"never heard {what} in {timeout} s") from None


async def ask_until(
    ask: Callable[[], Awaitable[T]], ok: Callable[[T], Any], what: str,
    timeout: float = 15.0, every: float = 0.05,
) -> T:
    """Await ``ask()`` every ``every`` s until its answer satisfies ``ok``: that answer
    (a ROS graph settles with no event). AssertionError naming ``what`` and the last answer
    after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        answer = await ask()
        if ok(answer):
            return answer
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} never satisfied the check; last answer {answer}")
        await asyncio.sleep(every)


def send_until_heard_sync(
    send: Callable[[], Any], listen: Callable[[float], T], what: str,
    attempt: float = 0.25, timeout: float = 20.0,
) -> T:
    """The blocking twin of :func:`send_until_heard` (``listen`` may also raise
    :class:`queue.Empty`)."""
    deadline = time.monotonic() + timeout
    while True:
        send()
        try:
            return listen(attempt)
        except (TimeoutError, AssertionError, queue.Empty):
            if time.monotonic() >= deadline:
                raise AssertionError(f"never heard {what} in {timeout} s") from None


class OpPeer:
    """A client's end that sends ops and awaits matching ones, over whatever carries its
    frames: :class:`WireClient` over a websocket, ``tests.session.harness.Client`` over a
    memory link. A subclass gives :meth:`send_raw`, :meth:`next_frame` and :meth:`close`."""

    def __init__(self) -> None:
        self.backlog: list[Any] = []

    async def send_raw(self, data: str | bytes) -> None:
        """Send one frame exactly as given (for malformed input)."""
        raise NotImplementedError

    async def next_frame(self, timeout: float = 10.0) -> str | bytes:
        """The next frame received, as it came (TimeoutError after ``timeout`` s)."""
        raise NotImplementedError

    async def close(self) -> None:
        """Close the connection."""
        raise NotImplementedError

    async def send(self, op: dict[str, Any]) -> None:
        """Send one op as a JSON text frame."""
        await self.send_raw(json.dumps(op))

    async def recv(self, timeout: float = 10.0) -> Any:
        """The next op, decoded (JSON text, or CBOR for binary frames)."""
        if self.backlog:
            return self.backlog.pop(0)
        return self._decode(await self.next_frame(timeout))

    @staticmethod
    def _decode(frame: str | bytes) -> Any:
        if isinstance(frame, bytes):
            import cbor2

            return cbor2.loads(frame)
        return json.loads(frame)

    async def expect(
        self, predicate: Callable[[Any], bool] | None = None, timeout: float = 10.0, **fields: Any
    ) -> Any:
        """Await the next op for which ``predicate`` holds and whose fields equal ``fields``.

        Ops that do not match are kept, in order, for later ``recv``/``expect`` calls.
        """

        def ok(op: Any) -> bool:
            if not isinstance(op, dict):
                return False
            if any(op.get(k) != v for k, v in fields.items()):
                return False
            return predicate is None or predicate(op)

        for i, op in enumerate(self.backlog):
            if ok(op):
                return self.backlog.pop(i)
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(
                    f"no op matching {fields} arrived in {timeout} s; got {self.backlog[-5:]}"
                )
            try:
                frame = await self.next_frame(left)
            except TimeoutError:
                continue
            op = self._decode(frame)
            if ok(op):
                return op
            self.backlog.append(op)


class WireClient(OpPeer):
    """A raw websocket peer for wire-level tests: send JSON ops, await matching ops."""

    def __init__(self, ws: ClientConnection) -> None:
        super().__init__()
        self.ws = ws

    async def send_raw(self, data: str | bytes) -> None:
        """Send one frame exactly as given (for malformed input)."""
        await self.ws.send(data)

    async def next_frame(self, timeout: float = 10.0) -> str | bytes:
        """The next frame received, as it came."""
        return await asyncio.wait_for(self.ws.recv(), timeout)

    async def close(self) -> None:
        """Close the connection."""
        await self.ws.close()


async def roundtrip(ws: OpPeer, id: str = "sync") -> None:
    """Send a cheap request and await its answer: everything sent before it has been handled."""
    await ws.send({"op": "call_service", "service": "/rosapi/get_ros_version", "id": id})
    await ws.expect(op="service_response", id=id)


async def sender_and_bystander(connect: Callable[[], Any]) -> tuple[OpPeer, OpPeer]:
    """Two peers from ``connect`` (a ``ws_connect`` fixture): the one that will send bad
    input, and a bystander whose session is up."""
    ws = await connect()
    other = await connect()
    await roundtrip(other, "before")
    return ws, other


async def still_working(ws: OpPeer, other: OpPeer, topic: str) -> None:
    """The sender's connection and a bystander's both still work (a publish/subscribe round
    trip on ``topic``_probe), and the bystander was sent no status."""
    await roundtrip(ws, "after")
    await roundtrip(other, "after-other")
    probe = topic + "_probe"
    await other.send({"op": "subscribe", "topic": probe, "type": "std_msgs/String"})
    await ws.send({"op": "advertise", "topic": probe, "type": "std_msgs/String"})
    await roundtrip(other, "subscribed")
    op = await send_until_heard(
        lambda: ws.send({"op": "publish", "topic": probe, "msg": {"data": "ok"}}),
        lambda wait: other.expect(op="publish", topic=probe, timeout=wait),
        "publish/subscribe working after the bad input", attempt=0.2, timeout=40)
    assert op["msg"]["data"].startswith("ok")
    assert [o for o in other.backlog if o.get("op") == "status"] == []


async def error_text(ws: OpPeer, **fields: Any) -> str:
    """The text of the next error status whose fields equal ``fields``."""
    status = await ws.expect(op="status", level="error", **fields)
    return str(status["msg"])


_rosapi_ids = itertools.count()


async def rosapi(ws: OpPeer, service: str, args: Any = None) -> dict[str, Any]:
    """Call the bridge's ``service`` (``/rosapi/...``) with ``args`` over ``ws``: its values,
    the call asserted to have succeeded."""
    rid = f"rosapi{next(_rosapi_ids)}"
    op: dict[str, Any] = {"op": "call_service", "service": service, "id": rid}
    if args is not None:
        op["args"] = args
    await ws.send(op)
    reply = await ws.expect(op="service_response", id=rid)
    assert reply["result"] is True, reply
    assert reply["service"] == service
    values: dict[str, Any] = reply["values"]
    return values


async def rosapi_until(
    ws: OpPeer, service: str, args: Any, ok: Callable[[dict[str, Any]], Any],
    timeout: float = 10.0,
) -> dict[str, Any]:
    """Call ``service`` (:func:`rosapi`) until its answer satisfies ``ok`` (a ROS graph takes
    a moment to settle: discovery has no event); the answer."""
    return await ask_until(lambda: rosapi(ws, service, args), ok, service, timeout, 0.02)


async def open_wire(url: str, **options: Any) -> WireClient:
    """Connect a :class:`WireClient` to ``url`` (no message size limit, 10 s to open;
    ``options`` go to :func:`websockets.asyncio.client.connect`)."""
    ws = await ws_connect(url, **{"max_size": None, "open_timeout": 10, **options})
    return WireClient(ws)


FIB = "test_msgs/action/Fibonacci"
"""The action type the action tests send goals of."""


def fib(order: int) -> list[int]:
    """The Fibonacci sequence test_msgs' examples compute for ``order``."""
    sequence = [0, 1]
    for i in range(1, order):
        sequence.append(sequence[i] + sequence[i - 1])
    return sequence


async def send_goal(ws: OpPeer, name: str, args: Any, id: str, **extra: Any) -> None:
    """Send a Fibonacci goal over ``ws``."""
    await ws.send({"op": "send_action_goal", "action": name, "action_type": FIB, "args": args,
                   "id": id, **extra})
