"""A session's two ports faked: a link that records the frames sent and feeds frames in, and
the smallest ROS graph the session tests need (no ROS, no socket).

:func:`open_session` runs a real :class:`~bridge_server.session.session.Session` over a
:class:`FakeLink`, sharing the state of a real (never started) ``Bridge`` over a
:class:`FakeGraph`.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager, nullcontext
from typing import Any, cast

from bridge_server.codec.encodings import EncodedMessage
from bridge_server.foxglove.session import FoxgloveSession
from bridge_server.interfaces import ConversionError, ServiceCallError, canonical_name
from bridge_server.security.auth import Principal
from bridge_server.server import Bridge, BridgeConfig, ServedGraph
from bridge_server.session.frames import Frame, Wire, joined
from bridge_server.session.session import Session
from roslibpy_lite.protocol.frames import decode_frame

__all__ = ["FakeGraph", "FakeLink", "LinkEnded", "open_foxglove", "open_session"]


class LinkEnded(Exception):
    """The fake link has ended (what writing and pinging raise then)."""


class _NoBytes:
    """A fake link takes whole frames (it is never ``framing``): no frame bytes."""

    def write(self, data: bytes) -> None:
        raise AssertionError("frame bytes written to a link that takes whole frames")

    def writelines(self, list_of_data: Any) -> None:
        raise AssertionError("frame bytes written to a link that takes whole frames")


class FakeLink:
    """A :class:`~bridge_server.session.link.ClientLink` in memory: :meth:`feed` hands the
    session a frame, :meth:`next_op` awaits the next one it sent (decoded)."""

    direct = True
    framing = False
    transport = _NoBytes()
    closed_errors: tuple[type[BaseException], ...] = (LinkEnded,)
    remote_address = ("192.0.2.7", 40000)
    address = "192.0.2.7:40000"

    def __init__(self, headers: Mapping[str, str] | None = None,
                 principal: Principal | None = None) -> None:
        self.headers = dict(headers or {})
        self.principal = principal
        self.inbox: asyncio.Queue[str | bytes | None] = asyncio.Queue()
        self.sent: asyncio.Queue[str | bytes] = asyncio.Queue()
        self.closed_with: tuple[int, str] | None = None
        self.closed_by_client = False
        self.ended = False

    # -- the test's side -------------------------------------------------------------------------

    def feed(self, frame: str | bytes | dict[str, Any]) -> None:
        """The client sends ``frame`` (a dict is sent as JSON text)."""
        self.inbox.put_nowait(json.dumps(frame) if isinstance(frame, dict) else frame)

    async def next_frame(self, timeout: float = 5.0) -> str | bytes:
        """The next frame the session sent, as it was sent."""
        return await asyncio.wait_for(self.sent.get(), timeout)

    async def next_op(self, timeout: float = 5.0) -> Any:
        """The next op the session sent, decoded (JSON text or CBOR)."""
        return decode_frame(await self.next_frame(timeout))

    def hang_up(self, by_client: bool = True) -> None:
        """The connection ends: closed by the client (1000), or lost (``by_client`` False)."""
        self.closed_by_client = by_client
        self._end()

    def _end(self) -> None:
        if not self.ended:
            self.ended = True
            self.inbox.put_nowait(None)

    # -- the session's side (ClientLink) -----------------------------------------------------------

    def header(self, name: str) -> str | None:
        """A header of the (imagined) handshake."""
        return self.headers.get(name)

    async def __aiter__(self) -> AsyncIterator[str | bytes]:
        while (frame := await self.inbox.get()) is not None:
            yield frame

    def hand_frames_to(self, handler: Callable[[str | bytes], None] | None) -> None:
        """Frames come through the iteration only."""

    def limit_frames(self, size: int | None) -> None:
        """No frame limit of its own."""

    def writable(self) -> bool:
        """Whether it takes frames (until it ends)."""
        return not self.ended

    def raw_ok(self) -> bool:
        """Never framed frames."""
        return False

    def write(self, frames: list[Frame]) -> None:
        """Record the frames sent."""
        if self.ended:
            raise LinkEnded("written after the end")
        for frame in frames:
            assert not isinstance(frame, Wire), "a framed frame sent to a whole-frame link"
            self.sent.put_nowait(joined(frame))

    def send_context(self) -> nullcontext[None]:
        """No flow control: it always takes more."""
        if self.ended:
            raise LinkEnded("written after the end")
        return nullcontext()

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """The session closes the link."""
        self.closed_with = (code, reason)
        self._end()

    def abort(self) -> None:
        """The link is dropped."""
        self._end()

    async def ping(self) -> asyncio.Future[float]:
        """Answered at once while the link is up."""
        if self.ended:
            raise LinkEnded("pinged after the end")
        pong: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        pong.set_result(0.0)
        return pong

    def watch(self, interval: float, timeout: float, dead: Callable[[float], None]) -> None:
        """No keepalive: nothing in memory falls silent."""
        return None


# -- the graph ---------------------------------------------------------------------------------

TYPES: dict[str, tuple[str, ...]] = {"std_msgs/msg/String": ("data",),
                                     "std_msgs/msg/Int32": ("data",)}
"""The message types the fake graph knows, and their fields."""


class FakeType:
    """A message type of the fake graph: its name and fields; a message is a dict."""

    def __init__(self, name: str) -> None:
        self.type_name = name
        self.fields = TYPES[name]

    def to_obj(self, msg: Any) -> dict[str, Any]:
        return dict(msg)

    def to_json(self, msg: Any) -> str:
        return json.dumps(msg)

    def to_cbor_obj(self, msg: Any) -> Any:
        return dict(msg)

    def from_obj(self, obj: Any, path: str = "") -> Any:
        """The message ``obj`` describes; a field it lacks or has too many is an error."""
        if not isinstance(obj, dict):
            raise ConversionError(path, self.type_name, obj)
        for key in obj:
            if key not in self.fields:
                raise ConversionError(f"{path}.{key}", self.type_name,
                                      detail=f"{self.type_name} has no field {key!r}")
        return {f: obj.get(f) for f in self.fields}


class FakeMessage(EncodedMessage):
    """A message the fake graph delivers to its subscribers."""

    __slots__ = ("msg",)

    def __init__(self, topic: str, msg: dict[str, Any]) -> None:
        super().__init__(topic, b"", 0)
        self.msg = msg

    def message_json(self) -> str:
        return json.dumps(self.msg)

    def cbor_obj(self) -> Any:
        return self.msg


class FakeFeed:
    """A topic the fake graph is subscribed to, with its listeners."""

    def __init__(self, topic: str, msg_cls: FakeType | None) -> None:
        self.topic = topic
        self.msg_cls = msg_cls
        self.received = 0
        self.latched: FakeMessage | None = None
        self.listeners: list[Callable[[Any], None]] = []

    @property
    def type_name(self) -> str | None:
        return None if self.msg_cls is None else self.msg_cls.type_name


class FakePublisher:
    """A publisher of the fake graph: what it published."""

    def __init__(self, topic: str, conv: FakeType) -> None:
        self.topic = topic
        self.conv = conv
        self.type_name = conv.type_name
        self.published: list[Any] = []

    def publish(self, msg: Any) -> None:
        self.published.append(msg)


class FakeGraph:
    """The ROS side in memory, as far as the session tests go: topics typed by
    :data:`TYPES`, publishers that record, subscriptions a test delivers to
    (:meth:`deliver`), services answered by a Python function (or never)."""

    name = "fake"

    def __init__(self) -> None:
        self.subscriptions: dict[str, FakeFeed] = {}
        self.publishers: dict[tuple[str, str, bool], FakePublisher] = {}
        self.services: dict[str, Callable[[Any], dict[str, Any]] | None] = {}
        """Service name -> its answer to a request (``None``: it never answers)."""

    # -- types -----------------------------------------------------------------------------------

    def resolve_message(self, name: str) -> FakeType:
        return FakeType(canonical_name(name, "msg"))

    def topic_types(self, topic: str) -> list[str]:
        feed = self.subscriptions.get(topic)
        return [] if feed is None or feed.type_name is None else [feed.type_name]

    def publisher_types(self, topic: str) -> set[str]:
        return {t for (name, t, _latch) in self.publishers if name == topic}

    # -- topics ----------------------------------------------------------------------------------

    def acquire_publisher(self, topic: str, msg_cls: FakeType, latch: bool, depth: int
                          ) -> FakePublisher:
        key = (topic, msg_cls.type_name, latch)
        pub = self.publishers.get(key)
        if pub is None:
            pub = self.publishers[key] = FakePublisher(topic, msg_cls)
        return pub

    def release_publisher(self, pub: FakePublisher) -> None:
        for key, held in list(self.publishers.items()):
            if held is pub:
                del self.publishers[key]

    def subscribe(self, topic: str, msg_cls: FakeType | None, listener: Callable[[Any], None]
                  ) -> FakeFeed:
        feed = self.subscriptions.get(topic)
        if feed is None:
            feed = self.subscriptions[topic] = FakeFeed(topic, msg_cls)
        elif feed.msg_cls is None:
            feed.msg_cls = msg_cls
        if listener not in feed.listeners:
            feed.listeners.append(listener)
        return feed

    def unsubscribe(self, feed: FakeFeed, listener: Callable[[Any], None]) -> None:
        if listener in feed.listeners:
            feed.listeners.remove(listener)
        if not feed.listeners:
            self.subscriptions.pop(feed.topic, None)

    def deliver(self, topic: str, msg: dict[str, Any]) -> None:
        """A message arrives on ``topic`` from ROS: every subscriber of it gets it."""
        feed = self.subscriptions[topic]
        feed.received += 1
        message = FakeMessage(topic, msg)
        for listener in list(feed.listeners):
            listener(message)

    # -- services --------------------------------------------------------------------------------

    async def call_service(self, service: str, srv_type: str | None, args: Any,
                           timeout: float, discovery_wait: float,
                           check: Callable[[Any], str | None] | None = None) -> dict[str, Any]:
        if service not in self.services:
            raise ServiceCallError(f"service {service} is not in the ROS graph")
        answer = self.services[service]
        if answer is None:  # it never answers: the caller's timeout runs out
            try:
                async with asyncio.timeout(timeout):
                    await asyncio.get_running_loop().create_future()
            except TimeoutError:
                raise ServiceCallError(f"{service}: no answer within {timeout:g} s") from None
        assert answer is not None
        return answer(args)

    # -- what the Foxglove hub lists ----------------------------------------------------------------

    def topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        return [(t, [f.type_name]) for t, f in self.subscriptions.items() if f.type_name]

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        return []

    def server_count(self, service: str) -> int:
        return 0

    # -- the ServedGraph's life (the bridge never starts it here) ------------------------------------

    def start(self) -> None:
        """Nothing to start."""

    def refresh(self) -> None:
        """Nothing to refresh."""

    def close(self) -> None:
        """Nothing to release."""


@asynccontextmanager
async def open_foxglove(link: FakeLink | None = None
                        ) -> AsyncIterator[tuple[FoxgloveSession, FakeLink, FakeGraph]]:
    """A Foxglove session running over ``link``, as :func:`open_session` a rosbridge one."""
    graph = FakeGraph()
    link = link or FakeLink()
    bridge = Bridge(BridgeConfig(), cast(ServedGraph, graph))
    session = FoxgloveSession(bridge, bridge.foxglove, link, 1)
    running = asyncio.create_task(session.run())
    try:
        yield session, link, graph
    finally:
        link.hang_up()
        await asyncio.wait_for(running, 5.0)
        await bridge.foxglove.close()


@asynccontextmanager
async def open_session(graph: FakeGraph | None = None, link: FakeLink | None = None,
                       ) -> AsyncIterator[tuple[Session, FakeLink, FakeGraph, Bridge]]:
    """A session running over ``link`` (a new one by default), sharing a never-started
    bridge's state over ``graph``; the link is hung up and the session ended on the way out."""
    graph = graph or FakeGraph()
    link = link or FakeLink()
    bridge = Bridge(BridgeConfig(), cast(ServedGraph, graph))
    session = Session(bridge, link, 1)
    bridge.sessions.add(session)
    running = asyncio.create_task(session.run())
    try:
        yield session, link, graph, bridge
    finally:
        link.hang_up()
        await asyncio.wait_for(running, 5.0)
