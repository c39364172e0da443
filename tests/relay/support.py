"""A whole relay tier in this process: a relay that is the Zenoh router, and a robot (a real
rclpy Graph, the bridge's own, without a websocket listener) whose exporter dials out to it.

Everything is real: the Zenoh router and links, the rclpy node, the websocket server; only
the processes are one.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import queue
import re
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge_server.front.server import Bridge, BridgeConfig, default_node_name
from bridge_server.rclpy_graph.graph import RclpyGraph
from bridge_server.zenoh.exporter import Exporter
from bridge_server.zenoh.graph import TypeLimits
from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.relay import Relay
from rosbridge_core.security import SecurityConfig
from rosbridge_core.security.auth import hash_token, new_token
from tests.helpers import async_wait_until
from tests.helpers import free_port as free_port  # where the relay tests have found it

ROBOT = "robot1"
ROBOT1_VIEWER = """
[roles.robot1_viewer]
subscribe = ["*"]
introspection = ["*"]
robots = ["robot1"]
"""
"""An auth file's role that sees robot1 alone (a relay's ``robots`` limit)."""


@dataclass
class Tier:
    """The relay, the robot's bridge and exporter, and where clients connect."""

    relay: Relay
    robot: Bridge
    exporter: Exporter
    router: str

    def url(self, robot: str = ROBOT) -> str:
        """The websocket URL of ``robot`` through the relay."""
        return f"ws://127.0.0.1:{self.relay.port}/{robot}"

    def direct_url(self) -> str:
        """The websocket URL of the robot's own bridge (a tier made with ``websocket``)."""
        return f"ws://127.0.0.1:{self.robot.port}"

    def demand(self, topic: str) -> set[str]:
        """The relays watching ``topic`` as the robot's exporter knows them."""
        export = self.exporter.exports.get(topic)
        return set(export.relays) if export is not None else set()


async def start_relay(router: str | None = None, listen: str | None = None,
                      relay_id: str | None = None, cert: str | None = None,
                      type_limits: TypeLimits | None = None) -> Relay:
    """A relay on an ephemeral port: the router (``listen``; ``cert`` a PEM with the key and
    the certificate chain for a tls/ endpoint) or a client of ``router``; ``type_limits``
    what it takes of each robot's types."""
    options = ZenohOptions(listen=[listen] if listen else [],
                           connect=[router] if router and not listen else [],
                           tls_cert=cert, tls_key=cert)
    relay = Relay(BridgeConfig(port=0, node_name="relay"), options, relay_id, type_limits)
    await relay.start()
    return relay


_ROBOT_BRIDGES = itertools.count(1)


async def start_robot(router: str, robot: str = ROBOT, ca: str | None = None,
                      websocket: bool = False) -> tuple[Bridge, Exporter]:
    """The robot's bridge (rclpy; a listener on an ephemeral port only with ``websocket``)
    and its exporter, dialing out to ``router`` (``ca``: the CA of a tls/ router's
    certificate)."""
    # A node name of its own: graph queries by node name (a test's look for the robot's
    # action clients) must not find another bridge of this process still in the graph.
    config = BridgeConfig(websocket=websocket, port=0, refresh_interval=0.1,
                          node_name=f"{default_node_name()}_robot{next(_ROBOT_BRIDGES)}")
    graph = RclpyGraph(asyncio.get_running_loop(), name=config.node_name)
    bridge = Bridge(config, graph)
    await bridge.start()
    exporter = Exporter(bridge.graph, robot, ZenohOptions(connect=[router], tls_ca=ca),
                        graph_changed=bridge.graph_changed, snapshot_interval=0.2)
    exporter.start()
    return bridge, exporter


async def robot_reachable(relay: Relay, robot: str = ROBOT, timeout: float = 20.0,
                          open_it: bool = True) -> None:
    """Wait until ``relay`` serves ``robot`` (its liveliness reached the relay); without
    ``open_it`` only until the robot is on the relay's Zenoh network (left unopened)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while not (await relay.robot(robot) if open_it else robot in await relay.on_network()):
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"robot {robot} never reached the relay")


@contextlib.asynccontextmanager
async def tier(tls: tuple[str, str] | None = None, websocket: bool = False
               ) -> AsyncIterator[Tier]:
    """A relay (the router) and a robot connected to it; all closed afterwards. ``tls``:
    (CA file, the router's key and certificate file) for a tls/ link; ``websocket``: the
    robot's bridge listens too (:meth:`Tier.direct_url`), to hold the relay to it."""
    scheme = "tls" if tls else "tcp"
    router = f"{scheme}/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router, cert=tls[1] if tls else None)
    robot, exporter = await start_robot(router, ca=tls[0] if tls else None, websocket=websocket)
    t = Tier(relay, robot, exporter, router)
    try:
        await robot_reachable(relay)
        yield t
    finally:
        # A test may have put a new robot in (a restarted one): close what is there now, and
        # the first one too (closing twice is harmless); a robot left open keeps its ROS
        # spin thread alive, and the interpreter waits for it at exit.
        await relay.close()
        for e in {id(x): x for x in (exporter, t.exporter)}.values():
            await e.close()
        for b in {id(x): x for x in (robot, t.robot)}.values():
            await b.close()


@contextlib.asynccontextmanager
async def relay_with_auth(auth: Path, roles: str, robots: tuple[str, ...] = ("robot1", "robot2"),
                          open_robots: bool = True
                          ) -> AsyncIterator[tuple[Relay, dict[str, str]]]:
    """A relay (the router) with the auth file ``auth`` written from the ``[roles.*]`` text
    ``roles`` and one principal, with a token of its own, per role; ``robots`` dialing out to
    it (opened by the relay unless not ``open_robots``). Yields the relay and the tokens by
    role name."""
    names = re.findall(r"^\[roles\.(\w+)\]", roles, re.MULTILINE)
    tokens = {role: new_token() for role in names}
    auth.write_text(roles + "".join(
        f'\n[principals.{role}_user]\nrole = "{role}"\ntoken_hash = "{hash_token(token)}"\n'
        for role, token in tokens.items()))
    async with relay_serving(robots, SecurityConfig(auth_file=str(auth)),
                             open_robots) as relay:
        yield relay, tokens


@contextlib.asynccontextmanager
async def relay_serving(robots: tuple[str, ...], security: SecurityConfig | None = None,
                        open_robots: bool = True) -> AsyncIterator[Relay]:
    """A relay (the router; ``security`` its options) with ``robots`` dialing out to it,
    each reachable (and opened, unless not ``open_robots``); all closed afterwards."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Relay(BridgeConfig(port=0, node_name="relay", security=security or SecurityConfig()),
                  ZenohOptions(listen=[router]))
    await relay.start()
    started = []
    try:
        for name in robots:
            started.append(await start_robot(router, robot=name))
        for name in robots:
            await robot_reachable(relay, name, open_it=open_robots)
        yield relay
    finally:
        await relay.close()
        for bridge, exporter in started:
            await exporter.close()
            await bridge.close()


@contextlib.contextmanager
def lone_session() -> Iterator[Any]:
    """A real Zenoh session alone (no scouting, no endpoints), closed after."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    session = zenoh.open(conf)
    try:
        yield session
    finally:
        session.close()  # type: ignore[no-untyped-call]


async def until(predicate: Any, what: str, timeout: float = 15.0) -> Any:
    """Await ``predicate()`` being truthy (Zenoh and ROS discovery have no event here):
    :func:`tests.helpers.async_wait_until` with the relay tests' order and deadline."""
    return await async_wait_until(predicate, timeout, what)


async def until_async(check: Callable[[], Awaitable[bool]], what: str, timeout: float = 15.0
                      ) -> None:
    """Await ``check()`` being true (it asks the network each time: a liveliness query, no
    event to wait on), at most ``timeout`` s."""
    deadline = asyncio.get_running_loop().time() + timeout
    while not await check():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")


@dataclass
class PlayedRobot:
    """A robot played by a plain Zenoh session (no ROS): alive, answering the relay's graph
    query with ``snapshot``; what it puts is up to the test (a malicious robot is easy)."""

    name: str
    session: Any
    snapshot: Any
    held: list[Any]

    def put(self, topic: str, data: bytes, type_name: str, seq: int) -> None:
        """One message on ``topic`` as an exporter puts it (CDR bytes and its Meta)."""
        from bridge_server.zenoh import keys
        from bridge_server.zenoh.keys import Meta

        self.session.put(keys.key_of(self.name, topic), data,
                         attachment=Meta(type=type_name, stamp_ns=1, epoch="e", seq=seq).encode())

    def leave(self) -> None:
        """Go away: the liveliness token and the graph queryable go."""
        for entity in self.held:
            entity.undeclare()
        self.held.clear()


@contextlib.asynccontextmanager
async def played_robot(relay: Relay | None, router: str, name: str, snapshot: Any
                       ) -> AsyncIterator[PlayedRobot]:
    """Robot ``name`` played on ``router`` (see :class:`PlayedRobot`), reachable by ``relay``
    (``None``: a relay in another process, not waited for)."""
    import zenoh

    from bridge_server.zenoh import keys
    from bridge_server.zenoh.link import open_session

    session = await open_session(ZenohOptions(connect=[router]))

    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, snapshot.encode())
        query.drop()  # type: ignore[no-untyped-call]

    robot = PlayedRobot(name, session, snapshot, [
        session.declare_queryable(f"{name}/{keys.GRAPH}", answer),
        session.liveliness().declare_token(f"{name}/{keys.ALIVE}")])
    try:
        if relay is not None:
            await robot_reachable(relay, name)
        yield robot
    finally:
        robot.leave()
        session.close()  # type: ignore[no-untyped-call]


def wait_matched(entity: Any, timeout: float = 20.0) -> None:
    """Wait until a Zenoh publisher has a subscriber, or a querier a queryable, that matches
    it (declarations travel apart from data: one declared a moment ago elsewhere may not
    have reached this session yet)."""
    matched: queue.Queue[bool] = queue.Queue()
    listener = entity.declare_matching_listener(lambda status: matched.put(status.matching))
    try:
        if not entity.matching_status.matching:
            while not matched.get(timeout=timeout):
                pass
    finally:
        listener.undeclare()


async def relay_reaches(relay: Relay, key: str) -> None:
    """Wait until ``relay``'s own Zenoh session has a queryable for ``key`` to ask (one a
    test just declared on a played robot's session)."""
    assert relay.session is not None
    querier = relay.session.declare_querier(key)
    try:
        await asyncio.to_thread(wait_matched, querier)
    finally:
        querier.undeclare()  # type: ignore[no-untyped-call]
