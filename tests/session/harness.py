"""A session on its ports in memory: the test's end of a
:class:`~rosbridge_core.memory.link.MemoryLink`, and a robot node of a
:class:`~rosbridge_core.memory.graph.MemoryRos` (no ROS, no socket, nothing of the server's
packages).

:func:`open_session` runs a real :class:`~rosbridge_core.session.session.Session` over a
:class:`Client`'s link, sharing the state of a
:class:`~rosbridge_core.memory.server.MemoryServer` (with the bridge's session settings and a
resume store that keeps a lost session) whose Graph is the node ``rosbridge`` of an
in-memory ROS graph; the :class:`Robot` is another node of it.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from typing import Any

from rosbridge_core.graph import Message, RosCall
from rosbridge_core.memory.graph import MemoryPublisher, MemoryRos
from rosbridge_core.memory.link import MemoryLink
from rosbridge_core.memory.server import MemoryServer
from rosbridge_core.protocol.frames import decode_frame
from rosbridge_core.security.auth import Principal
from rosbridge_core.session.resume import ResumeConfig
from rosbridge_core.session.session import Session, SessionConfig
from tests.op_peer import OpPeer

__all__ = ["Bench", "Client", "Robot", "open_session"]


class Client(OpPeer):
    """A client's end of a :class:`MemoryLink`: :meth:`feed` hands the session a frame,
    :meth:`next_op` awaits the next one it sent (decoded); as an
    :class:`~tests.op_peer.OpPeer` it sends ops and awaits matching ones as a websocket
    peer of the bridge does."""

    def __init__(self, headers: Mapping[str, str] | None = None,
                 principal: Principal | None = None) -> None:
        super().__init__()
        self.sent: asyncio.Queue[str | bytes] = asyncio.Queue()
        self.link = MemoryLink(self.sent.put_nowait, headers=headers,
                               address="192.0.2.7:40000")
        self.link.principal = principal

    def feed(self, frame: str | bytes | dict[str, Any]) -> None:
        """The client sends ``frame`` (a dict is sent as JSON text)."""
        self.link.receive(json.dumps(frame) if isinstance(frame, dict) else frame)

    async def next_frame(self, timeout: float = 10.0) -> str | bytes:
        """The next frame the session sent, as it was sent."""
        return await asyncio.wait_for(self.sent.get(), timeout)

    async def next_op(self, timeout: float = 10.0) -> Any:
        """The next op the session sent, decoded (JSON text or CBOR)."""
        return decode_frame(await self.next_frame(timeout))

    def hang_up(self, by_client: bool = True) -> None:
        """The connection ends: closed by the client, or lost (``by_client`` False)."""
        self.link.drop(by_client=by_client)

    async def send_raw(self, data: str | bytes) -> None:
        """Send one frame exactly as given."""
        self.feed(data)

    async def close(self) -> None:
        """The client closes the connection."""
        self.hang_up()


class Robot:
    """Another node of the bridge's in-memory ROS graph: it hears topics, publishes and
    serves."""

    def __init__(self, ros: MemoryRos) -> None:
        self.node = ros.node("robot")
        self.held: dict[str, asyncio.Queue[tuple[dict[str, Any], Callable[[dict[str, Any]], Any]]]
                        ] = {}
        """Per service served with no answer, its calls not answered yet (and their requests)."""
        self._pubs: dict[tuple[str, str], MemoryPublisher] = {}

    def hear(self, topic: str, type_name: str) -> list[dict[str, Any]]:
        """Subscribe to ``topic``: the list filled with each message heard, as a dict."""
        heard: list[dict[str, Any]] = []

        def listener(msg: Message) -> None:  # the op a client would get, its msg kept
            heard.append(json.loads(msg.json_text())["msg"])

        self.node.subscribe(topic, self.node.resolve_message(type_name), listener)
        return heard

    def advertise(self, topic: str, type_name: str) -> MemoryPublisher:
        """This node's publisher of ``topic`` (made at the first call)."""
        pub = self._pubs.get((topic, type_name))
        if pub is None:
            cls = self.node.resolve_message(type_name)
            pub = self._pubs[(topic, type_name)] = self.node.acquire_publisher(
                topic, cls, False, 10)
        return pub

    def publish(self, topic: str, type_name: str, msg: dict[str, Any]) -> None:
        """Publish ``msg`` on ``topic``: every subscriber in the graph gets it now."""
        pub = self.advertise(topic, type_name)
        pub.publish(pub.conv.from_obj(msg))

    def serve(self, service: str, type_name: str,
              answer: Callable[[dict[str, Any]], dict[str, Any]] | None) -> None:
        """Serve ``service``: each request (as a dict) answered with ``answer``'s response,
        or held (``answer`` None) until :meth:`answer_held` answers it."""
        srv_cls = self.node.resolve_service(type_name)
        request = self.node.converter(srv_cls.Request)
        response = self.node.converter(srv_cls.Response)
        held = self.held.setdefault(service, asyncio.Queue())

        def on_request(call: RosCall) -> None:
            if answer is None:
                held.put_nowait((request.to_obj(call.request),
                                 lambda values: call.complete(response.from_obj(values))))
            else:
                call.complete(response.from_obj(answer(request.to_obj(call.request))))

        self.node.serve(service, srv_cls, on_request)

    async def answer_held(self, service: str, response: dict[str, Any]) -> dict[str, Any]:
        """Answer the oldest call held by ``service`` (awaiting it) with ``response``: the
        request it answered, as a dict."""
        args, complete = await asyncio.wait_for(self.held[service].get(), 10.0)
        complete(response)
        return args

    def call(self, service: str, type_name: str, args: dict[str, Any],
             timeout: float = 10.0) -> asyncio.Task[dict[str, Any]]:
        """Call ``service`` (served by a client of the bridge, or by anyone): the task of
        its answer, as a dict."""
        return asyncio.ensure_future(
            self.node.call_service(service, type_name, args, timeout, timeout))


class Bench:
    """A :class:`MemoryServer` with the bridge's session settings and resume store, over the
    node ``rosbridge`` of a new in-memory graph, whose :attr:`robot` is another node of
    it; :meth:`connect` runs a session for a client, :meth:`close` ends them all."""

    def __init__(self) -> None:
        ros = MemoryRos()
        self.server = MemoryServer(ros.node("rosbridge"), config=SessionConfig(),
                                   resume=ResumeConfig())
        self.robot = Robot(ros)
        self._running: list[tuple[Client, asyncio.Task[None]]] = []

    def connect(self, client: Client | None = None) -> tuple[Session, Client]:
        """A session running over ``client``'s link (a new client by default)."""
        client = client or Client()
        session = Session(self.server, client.link, len(self._running) + 1)
        self.server.sessions.add(session)
        self._running.append((client, asyncio.create_task(session.run())))
        return session, client

    async def close(self) -> None:
        """Hang up every client's link, wait for each session to end, end the server."""
        for client, _ in self._running:
            client.hang_up()
        await asyncio.wait_for(asyncio.gather(*(t for _, t in self._running)), 5.0)
        await self.server.close()


@asynccontextmanager
async def open_session(client: Client | None = None,
                       ) -> AsyncIterator[tuple[Session, Client, Robot, MemoryServer]]:
    """A session running over ``client``'s link (a new client by default) on a new
    :class:`Bench`; every link is hung up and every session ended on the way out."""
    bench = Bench()
    session, client = bench.connect(client)
    try:
        yield session, client, bench.robot, bench.server
    finally:
        await bench.close()
