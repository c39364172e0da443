"""``roslibpy-lite-relay``: a rosbridge v2 server without ROS, serving robots on Zenoh.

Clients connect to ``ws://relay:9090/<robot>`` (``wss://`` with ``--certfile``): the path
names the robot. Each robot gets one :class:`~bridge_server.front.server.Bridge` (its sessions,
owners, metrics, kept sessions) over one :class:`~.graph.ZenohGraph`, made when its first
client comes and shared by the later ones; every robot's sessions are served on the one
port with the bridge's own session, security and resume code. A path naming no robot that
is on the Zenoh network is refused (404, naming it) before the handshake.

``--zenoh-listen tcp/0.0.0.0:7447`` makes the relay the Zenoh router itself (robots and
other relays connect to it); ``--zenoh-connect`` makes it a client of routers. Two relays
on one router serve the same robots: each robot's messages cross its uplink once, whatever
the number of relays and viewers.

Plain GETs on the same port show the relay's robots and each robot's bridge status page
and metrics (:mod:`bridge_server.zenoh.relay_web`).

It listens at once; until its Zenoh router answers (``--zenoh-connect`` to a router that is
not up yet) a client is refused with 503 naming why (``Retry-After: 1``) and ``/readyz``
answers 503. It logs ``relay listening on ws://HOST:PORT`` once it serves (listening and
on Zenoh) and stops within about a second of SIGINT or SIGTERM. A router that goes away
later is reported to each robot's clients as a warning status, its return as info.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import secrets
import signal
import sys
from typing import TYPE_CHECKING, Any

from bridge_server._exit import ends_process
from bridge_server.allocator import tune_allocator

try:
    from websockets.asyncio.server import Server, ServerConnection, serve
    from websockets.datastructures import MultipleValuesError
    from websockets.exceptions import ConnectionClosed

    from bridge_server import eventloop
    from bridge_server.foxglove import SUBPROTOCOL as FOXGLOVE
    from bridge_server.foxglove import select_subprotocol
    from bridge_server.front.handshake import Security
    from bridge_server.front.server import REFUSALS, Bridge, BridgeConfig, websockets_pings
    from bridge_server.front.websocket import BridgeConnection
    from bridge_server.http.web import Reply, address_of, handshake_headers, respond
    from bridge_server.http.web_access import WebAccess
    from bridge_server.zenoh import inbox as zenoh_inbox
    from bridge_server.zenoh import keys
    from bridge_server.zenoh import link as zenoh_link
    from bridge_server.zenoh.forget import Forgetter
    from bridge_server.zenoh.graph import ZenohGraph
    from bridge_server.zenoh.refusals import RobotRefusals, reading_zenoh_log
    from bridge_server.zenoh.relay_web import RelayWeb
    from bridge_server.zenoh.typestore import (
        MAX_DEFINITION_BYTES,
        MAX_FIELDS,
        MAX_TYPES_PER_ROBOT,
        TypeLimits,
    )
    from rosbridge_core import security
    from rosbridge_core.codec import budget as decode_budget
    from rosbridge_core.interfaces import BridgeError
    from rosbridge_core.protocol import ops
    from rosbridge_core.protocol.constants import DEFAULT_PORT, POLICY_VIOLATION
    from rosbridge_core.protocol.errors import ProtocolError
    from rosbridge_core.protocol.frames import decode_frame
    from rosbridge_core.protocol.ops import RELAY_HEADER, parse_op
    from rosbridge_core.security.auth import Principal
    from rosbridge_core.security.credentials import client_address
    from rosbridge_core.security.options import MAX_MESSAGE_SIZE
    from rosbridge_core.session.resume import ResumeConfig
    from rosbridge_core.session.session import SessionConfig
except ModuleNotFoundError as _missing:  # an install without the relay extra
    from bridge_server._requires import missing_dependency

    missing_dependency(_missing, "relay")

if TYPE_CHECKING:
    import zenoh
    from websockets.http11 import Request, Response

    from bridge_server.foxglove.session import FoxgloveSession
    from rosbridge_core.session.session import Session

__all__ = ["Relay", "main", "parse_args"]

log = logging.getLogger("bridge_server.relay")

ALIVE_WAIT = 2.0
"""Seconds a robot's liveliness is asked for when a client names it."""


class Relay:
    """The relay: one websocket port, one Zenoh session, one Bridge per robot served."""

    def __init__(self, config: BridgeConfig, options: zenoh_link.ZenohOptions,
                 relay_id: str | None = None, type_limits: TypeLimits | None = None,
                 robot_refusals: RobotRefusals | None = None) -> None:
        self.config = config
        self.options = options
        self.type_limits = type_limits or TypeLimits()  # of each robot's own types
        self.relay_id = keys.check_relay(_relay_id(options, relay_id))
        self.security = Security(config.security)
        self.robots: dict[str, Bridge] = {}
        self.session: zenoh.Session | None = None
        self._server: Server | None = None
        self._opening: dict[str, asyncio.Task[Bridge | None]] = {}
        self.refused: dict[str, int] = {}  # clients turned away before a robot, by reason
        self.claims: dict[str, keys.Claims] = {}
        """The sessions announcing each robot name (their ``@claim`` tokens), in order."""
        self.names_refused: dict[str, dict[str, Any]] = {}
        """Robots refused a name another robot held, by name: how many, and the last
        (``holder``, ``refused``: Zenoh ids with their addresses where this relay knows
        them)."""
        self._watch: Any = None
        self.robot_refusals = robot_refusals or RobotRefusals(options.robots, options.relays,
                                                              options.listen)
        """Robots this relay's router did not admit (it is their router with mTLS)."""
        self._links: Any = None
        self.web = RelayWeb(self, WebAccess(self.security))  # status page, /metrics
        self.forgetter = Forgetter(self.robots)  # robots that left and nobody waits for

    @property
    def port(self) -> int:
        """The websocket port actually bound."""
        assert self._server is not None
        return int(next(iter(self._server.sockets)).getsockname()[1])

    async def start(self) -> None:
        """Listen, then join Zenoh (until a router answers, clients are answered 503); what
        opened is closed again if joining fails."""
        await self.listen()
        try:
            await self.join()
        except BaseException:
            await self.close()
            raise

    async def join(self) -> None:
        """Join the Zenoh network (a client of routers waits here until one answers)."""
        self.session = await zenoh_link.open_session(self.options)
        loop = asyncio.get_running_loop()

        def cross(sample: zenoh.Sample) -> None:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._on_claim, sample)

        self._watch = self.session.liveliness().declare_subscriber(
            f"*/{keys.CLAIM}/*", cross, history=True)
        if self.options.listen and self.options.mtls:  # the robots' router: who it refuses
            self._links = self.session.info.declare_link_events_listener(
                self.robot_refusals.on_link, history=True)
        self.forgetter.start()

    def _on_claim(self, sample: zenoh.Sample) -> None:
        """A robot's ``@claim`` token came or went: one coming while another robot holds its name is
        refused (the holder is served; the refused robot withdraws when it sees the holder's
        token): logged with both Zenoh ids and addresses, and counted."""
        import zenoh

        robot, zid = keys.parse_alive(str(sample.key_expr))
        claims = self.claims.setdefault(robot, keys.Claims())
        if not claims.seen(zid, sample.kind == zenoh.SampleKind.PUT):
            if claims.holder is None:
                del self.claims[robot]
            return
        holder, refused = self._whom(claims.holder or ""), self._whom(zid)
        entry = self.names_refused.setdefault(robot, {"count": 0})
        entry.update(count=entry["count"] + 1, holder=holder, refused=refused)
        log.warning("refused robot %s (%s): robot %s (%s) holds that name; this relay goes on "
                    "serving it", robot, refused, robot, holder)

    def _whom(self, zid: str) -> str:
        """A robot's Zenoh id, with its address (and certificate's name) where this relay
        has a link to it (it is the robot's router)."""
        assert self.session is not None
        for link in self.session.info.links():
            if str(link.zid) == zid:
                cn = f", certificate {link.auth_identifier}" if link.auth_identifier else ""
                return f"Zenoh id {zid} at {link.dst}{cn}"
        return f"Zenoh id {zid or '(none)'}"

    async def listen(self) -> None:
        """Open the websocket port (and its plain-HTTP routes)."""
        self._server = await serve(
            self._handle, self.config.host, self.config.port,
            max_size=self.config.max_message_size, write_limit=self.config.write_limit,
            compression=None, max_queue=64, close_timeout=1.0,
            **websockets_pings(self.config),
            process_request=self._process_request,
            select_subprotocol=select_subprotocol,  # foxglove.websocket.v1, else rosbridge
            process_response=self._process_response,
            **self.security.serve_kwargs(),
        )

    async def robot(self, name: str) -> Bridge | None:
        """The Bridge of robot ``name``, made on first use; ``None`` if it is not on Zenoh
        (or ``name`` is no robot name)."""
        bridge = self.robots.get(name)
        if bridge is not None:
            return bridge
        try:
            keys.check_robot(name)
        except BridgeError:
            return None
        opening = self._opening.get(name)
        if opening is None:  # one opening per robot, however many clients ask at once
            opening = self._opening[name] = asyncio.ensure_future(self._open_robot(name))
            opening.add_done_callback(lambda _: self._opening.pop(name, None))
        return await asyncio.shield(opening)

    async def _open_robot(self, name: str) -> Bridge | None:
        assert self.session is not None
        if not await self._alive(name):
            return None
        graph = ZenohGraph(self.session, name, self.relay_id, self.type_limits)
        bridge = Bridge(self.config, graph=graph)
        graph.presence_listeners.append(lambda here: _tell_presence(bridge, name, here))
        graph.inbox.told.append(lambda text: _tell(bridge, "warning", text))
        bridge.security = self.security  # one auth file, one SIGHUP, for every robot
        bridge.web.access = WebAccess(self.security, robot=name)
        bridge.web.serving = self._serving
        graph.start()
        if not await graph.ready():
            log.warning("robot %s sent no graph snapshot in time: serving it without", name)
        bridge.start_graph()
        await bridge.web.start()  # its rates, for its page
        self.robots[name] = bridge
        log.info("serving robot %s", name)
        return bridge

    async def _alive(self, name: str) -> bool:
        """Whether robot ``name``'s liveliness token is on the network."""
        return bool(await self._alive_tokens(name, first=True))

    async def on_network(self) -> set[str]:
        """The robots on the Zenoh network now (their liveliness tokens)."""
        return await self._alive_tokens("*")

    async def _alive_tokens(self, robots: str, first: bool = False) -> set[str]:
        """The robots matching ``robots`` whose liveliness tokens are on the network (with
        ``first``, as soon as one answers)."""
        if self.session is None:
            return set()
        found = await zenoh_link.tokens(self.session, f"{robots}/{keys.ALIVE}/**", ALIVE_WAIT,
                                        first)
        return {keys.parse_alive(key)[0] for key in found}

    def unknown(self, name: str) -> str:
        """What a client asking for robot ``name``, which is not on Zenoh, is told: that this
        relay refused it and why, if it did."""
        return self.robot_refusals.why(name) or _unknown(name)

    def robots_refused(self) -> dict[str, Any]:
        """Robots this relay's router refused: counts by reason, the last of each name."""
        return self.robot_refusals.snapshot()

    def _serving(self) -> bool:
        return self._server is not None and self._server.is_serving()

    def trouble(self) -> str | None:
        """Why the relay does not serve (``None``: it does)."""
        if self.session is None:
            return ("this relay has not reached its Zenoh router yet "
                    f"({', '.join(self.options.connect)})")
        return None if self._serving() else "not listening"

    async def _process_request(self, connection: ServerConnection, request: Request
                               ) -> Response | None:
        """Plain GETs are the status routes (relay_web.py). A websocket's path names the
        robot: refuse a path naming none on Zenoh, else hand the request to that robot's
        Bridge (security, session resume)."""
        if not any("upgrade" in v.lower() for v in request.headers.get_all("Connection")):
            reply = await self.web.answer(request, address_of(connection))
            return respond(connection, reply or Reply(404, b"no such page\n"))
        if self.session is None:  # no router yet: say so, and when to ask again
            log.info("refused a client: this relay has not reached its Zenoh router yet")
            response = self._refuse(connection, "no_router", 503,
                                    f"{self.trouble()}: try again shortly")
            response.headers["Retry-After"] = "1"
            return response
        name = request.path.partition("?")[0].strip("/").split("/")[0]
        if not name:
            return self._refuse(connection, "no_robot_named", 404,
                                "name a robot in the path: ws://<relay>:<port>/<robot>")
        try:
            keys.check_robot(name)
        except BridgeError as exc:
            return self._refuse(connection, "invalid_robot_name", 400, str(exc))
        try:
            refusal = await self.security.process_request(connection, request)
        except MultipleValuesError as exc:  # a header given twice that must be given once
            refusal = connection.respond(400, f"header {exc} sent more than once\n")
        if refusal is not None:  # origin, client limits, lock-out, a wrong token
            self._count(REFUSALS.get(refusal.status_code, f"http_{refusal.status_code}"))
            return refusal
        principal = getattr(connection, "principal", None)
        if principal is None and self.security.auth is not None:
            # No token yet: the robot is opened only once its first op authenticates a
            # principal that may reach it (_handle); nothing of the robot's is touched now.
            connection.robot_name = name  # type: ignore[attr-defined]
            return None
        if principal is not None and not principal.role.reaches(name):
            return self._not_allowed(connection, principal, name)
        bridge = await self.robot(name)
        if bridge is None:
            log.info("refused a client asking for robot %s: not on Zenoh", name)
            return self._refuse(connection, "unknown_robot", 404, self.unknown(name))
        connection.robot_bridge = bridge  # type: ignore[attr-defined]
        answer: Response | None = await bridge.admit(connection, request, secured=True)
        return answer

    def _not_allowed(self, connection: ServerConnection, principal: Principal, name: str
                     ) -> Response:
        """403: ``principal``'s role does not reach robot ``name`` (which stays unopened)."""
        log.warning("refused principal %s (role %s) asking for robot %s: not among its robots",
                    principal.name, principal.role.name, name)
        return self._refuse(connection, "robot_not_allowed", 403,
                            f"role {principal.role.name} may not reach robot {name!r}")

    def _refuse(self, connection: ServerConnection, reason: str, status: int, text: str
                ) -> Response:
        """Turn a client away before any robot's Bridge sees it, counted by ``reason`` (the
        relay's /metrics)."""
        self._count(reason)
        return connection.respond(status, f"{text}\n")

    def _count(self, reason: str) -> None:
        """One more client turned away for ``reason``."""
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def _process_response(self, connection: ServerConnection, request: Request,
                          response: Response) -> None:
        """The robot's Bridge names its session (resume), acknowledgements and a needed
        ``auth`` op in the handshake answer, as on the bridge (a connection whose robot waits
        for its ``auth`` op gets the last two); every websocket answer, a refusal too, names
        the robot asked for (:data:`RELAY_HEADER`), so a client knows a relay answered."""
        if any("upgrade" in v.lower() for v in request.headers.get_all("Connection")):
            response.headers[RELAY_HEADER] = _robot_named(request)
        bridge: Bridge | None = getattr(connection, "robot_bridge", None)
        if bridge is not None:
            bridge.web.process_response(connection, request, response)
        else:
            handshake_headers(connection, request, response, self.security.auth is not None)

    async def _handle(self, ws: ServerConnection) -> None:
        bridge: Bridge | None = getattr(ws, "robot_bridge", None)
        if bridge is None:
            bridge = await self._authenticated_robot(ws, ws.robot_name)  # type: ignore[attr-defined]
            if bridge is None:
                return
        await bridge.serve_connection(ws)

    async def _authenticated_robot(self, ws: ServerConnection, name: str) -> Bridge | None:
        """A connection that gave no token at the handshake: its first op must be ``auth``
        (within the handshake timeout), with a token whose role reaches robot ``name``; only
        then is the robot opened (``None``: the connection was closed, saying why)."""
        why: Principal | str
        if ws.subprotocol == FOXGLOVE:  # it has no auth op: a token at the handshake or none
            why = ("authentication required: give the token in the URL (?token=...) or an "
                   "Authorization header")
        else:
            why = await self._auth_op(ws)
        if isinstance(why, Principal):
            principal = why
            if not principal.role.reaches(name):
                log.warning("closed the connection of principal %s (role %s), authenticated "
                            "by an auth op, asking for robot %s: not among its robots",
                            principal.name, principal.role.name, name)
                self._count("robot_not_allowed")
                why = f"role {principal.role.name} may not reach robot {name!r}"
            else:
                bridge = await self.robot(name)
                if bridge is not None:
                    ws.principal = principal  # type: ignore[attr-defined]
                    if isinstance(ws, BridgeConnection):
                        ws.limit_frames(None)  # frames up to --max-message-size again
                    return bridge
                self._count("unknown_robot")
                why = self.unknown(name)
        if why:
            with contextlib.suppress(ConnectionClosed):
                await ws.close(POLICY_VIOLATION, why[:120])
        return None

    async def _auth_op(self, ws: ServerConnection) -> Principal | str:
        """The principal the connection's first op (``auth``) proves, or why it does not
        (empty: the connection is gone)."""
        try:
            async with asyncio.timeout(self.config.security.handshake_timeout or 10.0):
                op = parse_op(decode_frame(await ws.recv()))
        except TimeoutError:
            return ("authentication required: send a token (Authorization: Bearer, ?token= "
                    "or an auth op) within the handshake timeout")
        except ProtocolError as exc:
            return f"authentication required: the first op must be auth ({exc.message[:60]})"
        except ConnectionClosed:
            return ""
        if not isinstance(op, ops.Auth):
            return f"authentication required before {op.OP!r}: send the auth op first"
        return self.security.verify_auth_op(client_address(ws), op.mac,
                                            f"a client of {ws.robot_name}")  # type: ignore[attr-defined]

    def reload(self) -> bool:
        """SIGHUP: certificates and the auth file again, every robot's sessions rechecked."""
        gates = [s.gate for bridge in self.robots.values() for s in list(bridge.sessions)]
        gates += [s.gate for bridge in self.robots.values() for s in list(bridge.foxglove.sessions)]
        return self.security.reload(gates)

    async def close(self) -> None:
        """Close every robot's sessions, leave Zenoh."""
        self.forgetter.stop()
        if self._server is not None:
            self._server.close(close_connections=True)
        for bridge in list(self.robots.values()):
            await bridge.close()
        self.robots.clear()
        if self._server is not None:  # its port is free when this returns (at most ~1 s)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
        for watch in (self._watch, self._links):
            if watch is not None:
                with contextlib.suppress(Exception):  # the session closed first
                    watch.undeclare()
        self._watch = self._links = None
        if self.session is not None:
            from bridge_server.zenoh.replay import settle_aside

            session, self.session = self.session, None
            await asyncio.get_running_loop().run_in_executor(None, settle_aside)
            await asyncio.get_running_loop().run_in_executor(None, session.close)


def _relay_id(options: zenoh_link.ZenohOptions, given: str | None) -> str:
    """The relay's id on Zenoh: ``given`` (``--relay-id``), else its certificate's common
    name, else a random one. A relay that dials a router with a certificate is that
    certificate's name there (the router's access rules hold it to the keys naming it):
    another ``given`` is refused, naming both."""
    from bridge_server.zenoh.certs import common_name

    name = common_name(options.tls_cert) if options.tls_cert else None
    if given and name and options.connect and not options.listen and given != name:
        raise BridgeError(f"--relay-id {given}: a relay dialing with a certificate is its "
                          f"certificate's common name on Zenoh ({name}); leave --relay-id out "
                          "or give that")
    return given or name or secrets.token_hex(6)


def _unknown(name: str) -> str:
    return f"no robot named {name!r} is connected to this relay's Zenoh network"


def _tell_presence(bridge: Bridge, robot: str, here: bool) -> None:
    """Tell every client of ``robot`` that it went away (its link, or this relay's link to
    the router, is gone: what it does now waits) or that it is back."""
    if here:
        _tell(bridge, "info", f"robot {robot} is back: its topics flow again")
    else:
        _tell(bridge, "warning", f"robot {robot} went away: its link to the Zenoh network "
              "(or this relay's) is gone; subscriptions resume when it is back")


def _tell(bridge: Bridge, level: str, text: str) -> None:
    """A status to every client of a robot's bridge, rosbridge and Foxglove, whatever status
    level a rosbridge client set (rosbridge's default, ``error``, would hide it)."""
    sessions: list[Session | FoxgloveSession] = [*bridge.sessions, *bridge.foxglove.sessions]
    for session in sessions:
        session.status(level, text, always=True)


def _robot_named(request: Request) -> str:
    """The robot a websocket request's path names, if it is a valid name ('' if not)."""
    name = request.path.partition("?")[0].strip("/").split("/")[0]
    try:
        return keys.check_robot(name)
    except BridgeError:
        return ""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="roslibpy-lite-relay",
        description="A rosbridge v2 server without ROS: serves the robots that dial out to "
        "Zenoh (roslibpy-lite-bridge --zenoh-connect ... --robot NAME) at ws://HOST:PORT/NAME.",
        epilog="subcommand (with its own --help): certs (a fleet's CA and the mutual-TLS "
        "certificates of its relays and robots)",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"port (default {DEFAULT_PORT}; 0: any free port)")
    p.add_argument("--relay-id", default=None,
                   help="this relay's name on Zenoh (default: its certificate's common name "
                   "with --zenoh-tls-cert, else random; it names its tokens, goals and calls, "
                   "and a robot's goals answer to it alone)")
    p.add_argument("--max-message-size", type=int, default=MAX_MESSAGE_SIZE,
                   help=f"largest inbound frame in bytes (default {MAX_MESSAGE_SIZE // 2**20} "
                   "MiB)")
    p.add_argument("--call-timeout", type=float, default=SessionConfig.call_timeout,
                   help=f"default call_service timeout in seconds (default "
                   f"{SessionConfig.call_timeout:g})")
    p.add_argument("--session-keep", type=float, default=30.0,
                   help="seconds a dropped client's session is kept for it to resume "
                   "(default 30; 0: off)")
    p.add_argument("--max-definition-bytes", type=int, default=MAX_DEFINITION_BYTES,
                   help="largest type definition (with its dependencies) the relay builds a "
                   f"robot's type from, in bytes (default {MAX_DEFINITION_BYTES}); a robot's "
                   "type over it is refused and its messages dropped")
    p.add_argument("--max-types-per-robot", type=int, default=MAX_TYPES_PER_ROBOT,
                   help="most messages, services and actions the relay builds from one "
                   f"robot's definitions (default {MAX_TYPES_PER_ROBOT})")
    p.add_argument("--max-fields-per-type", type=int, default=MAX_FIELDS,
                   help="most fields and constants of one message in a robot's definition "
                   f"(default {MAX_FIELDS}); building a bigger one would stall every robot")
    p.add_argument("--log-level", default="INFO",
                   choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                   help="logging level (default INFO)")
    p.add_argument("--max-robot-message-bytes", type=int, default=zenoh_inbox.MESSAGE_BYTES,
                   help="largest message (or reply) the relay takes from a robot, in bytes "
                   f"(default {zenoh_inbox.MESSAGE_BYTES >> 20} MiB); a larger one is dropped "
                   "on arrival, counted and logged with its topic")
    decode_budget.add_arguments(p)
    eventloop.add_argument(p, "relay")
    security.add_arguments(p)
    zenoh_link.add_arguments(p, listen=True)
    return p.parse_args(argv)


async def _run(args: argparse.Namespace, robot_refusals: RobotRefusals | None = None) -> int:
    config = BridgeConfig(
        host=args.host, port=args.port, max_message_size=args.max_message_size,
        node_name="relay",
        session=SessionConfig(call_timeout=args.call_timeout),
        resume=ResumeConfig(session_keep=args.session_keep),
        security=security.config_from_args(args),
    )
    relay = Relay(config, zenoh_link.options_from_args(args), args.relay_id,
                  TypeLimits(args.max_definition_bytes, args.max_types_per_robot,
                             args.max_fields_per_type), robot_refusals)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await relay.listen()
    loop.add_signal_handler(signal.SIGHUP, relay.reload)
    scheme = "wss" if args.certfile else "ws"
    zenoh_where = (f"Zenoh router on {', '.join(args.zenoh_listen)}" if args.zenoh_listen
                   else f"Zenoh client of {', '.join(args.zenoh_connect)}")
    log.info("relay %s (%s): accepting on %s://%s:%d, joining Zenoh", relay.relay_id,
             zenoh_where, scheme, args.host, relay.port)
    log.info("event loop: %s", eventloop.loop_name(loop))
    relay.security.startup_warnings(args.host)
    joining = asyncio.ensure_future(relay.join())
    stopping = asyncio.ensure_future(stop.wait())
    await asyncio.wait({joining, stopping}, return_when=asyncio.FIRST_COMPLETED)
    if joining.done():
        joining.result()  # a session that cannot open (BridgeError) ends the relay
        log.info("relay listening on %s://%s:%d", scheme, args.host, relay.port)
        await stopping
    else:
        joining.cancel()
    log.info("relay shutting down")
    await relay.close()
    return 0


@ends_process  # as the program: its own status, whatever Zenoh's threads do at exit
def main(argv: list[str] | None = None) -> int:
    """Entry point of ``roslibpy-lite-relay`` and ``python -m bridge_server.zenoh.relay``
    (``roslibpy-lite-relay certs ...``: :mod:`bridge_server.zenoh.certs`)."""
    given = sys.argv[1:] if argv is None else argv
    if given[:1] == ["certs"]:
        from bridge_server.zenoh.certs import main as certs

        return certs(given[1:])
    args = parse_args(argv)
    tune_allocator()
    refusal = security.exposure_refusal(args) or zenoh_link.options_from_args(args).refusal()
    try:
        decode_budget.apply(args)
        zenoh_inbox.set_message_bytes(args.max_robot_message_bytes)
    except ValueError as exc:
        refusal = refusal or str(exc)
    if refusal is not None:
        print(f"roslibpy-lite-relay: refusing to start: {refusal}", file=sys.stderr)
        return 2
    robot_refusals = (reading_zenoh_log(args.zenoh_robot, args.zenoh_relay, args.zenoh_listen)
                      if args.zenoh_listen and args.zenoh_mtls else None)  # robots' router
    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    security.install_log_redaction()
    if args.log_level != "DEBUG":
        logging.getLogger("websockets").setLevel(logging.WARNING)
    try:
        security.check_readable(security.config_from_args(args))
        zenoh_link.options_from_args(args).config()  # a bad option named before anything
        with asyncio.Runner(loop_factory=eventloop.event_loop_factory(args.event_loop)) as runner:
            return runner.run(_run(args, robot_refusals))
    except (OSError, BridgeError) as exc:
        log.error("cannot start: %s", exc)
        return 1


if __name__ == "__main__":
    sys.exit(main())
