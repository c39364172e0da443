"""A relay's plain-HTTP routes: its robots at a glance, and each robot's bridge status page.

The relay (``roslibpy-lite-relay``) serves each robot's sessions with one
:class:`~bridge_server.front.server.Bridge`; these routes show them, with the bridge's own page,
snapshot and metrics code, on the relay's websocket port (a websocket upgrade on any path
goes on to the robot's handshake):

===========================  ===========================================================
``GET /``                    the relay's page (``static/relay.html``): its robots, each
                             linking to its own page
``GET /status.json``         the relay and, per robot: present on Zenoh or not, clients,
                             the topics its clients watch, messages and bytes each way,
                             and their ``rates`` per second over ``rate_window_s``
``GET /metrics``             every robot's bridge metrics (:mod:`.metrics`), each series
                             labelled ``robot``, ``roslibpy_relay_robot_present``,
                             ``roslibpy_relay_bytes_from_robot_total`` and
                             ``roslibpy_relay_robot_dropped_total`` (by robot; the latter
                             by kind too: what a robot sent that was dropped),
                             ``roslibpy_relay_connections_refused_total`` (by reason) and
                             ``roslibpy_relay_robot_names_refused_total`` (by robot name:
                             robots refused a name another robot held; ``status.json``
                             has them as ``names_refused``, with the Zenoh ids)
``GET /healthz``             the process runs
``GET /readyz``              Zenoh is joined and the port listens (else 503 and why)
``GET /robots/<robot>/``     the bridge's status page for that robot, and under it
                             ``status.json``, ``metrics``, ``readyz`` (the robot is on
                             Zenoh; with an auth file it needs a token, as the data
                             routes), as a bridge serves them (its ``status.json`` also
                             names the ``robot`` and the ``relay`` serving it); the
                             relay's page links here
``GET /<robot>/``            the same, for a robot not named like one of the relay's own
                             routes above (``metrics``, ``static``, ``robots``...)
===========================  ===========================================================

``/<robot>`` and ``/robots/<robot>`` without the slash are redirected to the page with it.
Every robot's page is reachable under ``/robots/``, whatever its name: robot names are
not refused for looking like a route (a robot named ``metrics`` dialed in and served over
websockets at ``ws://relay/metrics`` all along; a name refused when a robot joins would
stop a working robot at a relay's upgrade, and each new route would refuse another name).

Who sees what is the bridge's :class:`~.web_access.WebAccess`: with an auth file the data
routes need a token (``Authorization: Bearer`` or ``?token=``) of a role with
``introspection``; a role limited to some robots (``robots = [...]``) sees only those, in
the relay's lists, and is refused (403) another robot's page. A robot the relay does not
know of is 404. A robot no client has opened yet is opened (followed on Zenoh) only for a
viewer whose token may see its pages: 401/403 before anything of the robot is touched.
Without a token every robot name answers alike, whether a robot has it or not (issue 53):
the page and its files (the same for every robot) are served, and everything else under
``/robots/<robot>/`` (``readyz`` and ``healthz`` too) is 401, so no name can be found out.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Awaitable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from prometheus_client.core import CounterMetricFamily

from bridge_server.http import metrics
from bridge_server.http.rates import RATE_WINDOW, Window
from bridge_server.http.web import Reply, open_route, static_files, viewer, visible
from bridge_server.http.web_access import WebAccess
from bridge_server.zenoh.relay_status import (
    RobotStatus,
    robot_families,
    robot_status,
    robots_refused,
    robots_refused_family,
)

if TYPE_CHECKING:
    from websockets.http11 import Request

    from bridge_server.front.server import Bridge
    from bridge_server.zenoh.forget import Forgetter

__all__ = ["RelayFront", "RelayWeb"]

ROBOTS = "robots"
"""The first path chunk under which every robot's page is, by name (``/robots/<robot>/``)."""

RELAY_ROUTES = frozenset({"", "status.json", "metrics", "healthz", "readyz", "static", ROBOTS})
"""First path chunks that are the relay's own routes, not a robot's."""


class RelayFront(Protocol):
    """What the routes need of the relay (``bridge_server.zenoh.relay.Relay``)."""

    relay_id: str
    robots: dict[str, Bridge]
    refused: dict[str, int]
    """Clients turned away before any robot's Bridge saw them, by reason."""
    names_refused: dict[str, dict[str, Any]]
    """Robots refused a name another robot held, by name (``count``, ``holder``,
    ``refused``)."""
    forgetter: Forgetter
    """Lets go of the robots that left (``forgotten``, ``closing``)."""

    def robot(self, name: str) -> Awaitable[Bridge | None]:
        """Robot ``name``'s Bridge, opened on first use; ``None``: not on Zenoh."""

    def on_network(self) -> Awaitable[set[str]]:
        """The robots on Zenoh now (their liveliness tokens)."""

    def trouble(self) -> str | None:
        """Why the relay does not serve (``None``: it does)."""

    def robots_refused(self) -> dict[str, Any]:
        """Robots the relay's router refused (``counts`` by reason, ``robots`` by name)."""


class RelayWeb:
    """Answers the relay's plain GETs (see the module docstring)."""

    def __init__(self, relay: RelayFront, access: WebAccess) -> None:
        self.relay = relay
        self.access = access
        self.started = time.time()
        self._static = static_files()
        self.caps = metrics.new_caps()
        self.rates = Window()
        """The robots' counters as the relay's page asks for them: its rates per robot."""

    async def answer(self, request: Request, address: str) -> Reply | None:
        """The reply to a plain GET from ``address`` (``None``: no such route)."""
        path, _, query = request.path.partition("?")
        first, slash, rest = path.lstrip("/").partition("/")
        if first == ROBOTS:  # /robots/<robot>/...: any robot's page, whatever its name
            name, slash, rest = rest.partition("/")
            if not name:
                return _redirect("/", query)
            return await self._robot_page(name, f"/{ROBOTS}/{name}/", slash, rest, query,
                                          request, address)
        if first in RELAY_ROUTES:
            return await self._own(path, request, address)
        return await self._robot_page(first, f"/{first}/", slash, rest, query, request, address)

    async def _robot_page(self, name: str, home: str, slash: str, rest: str, query: str,
                          request: Request, address: str) -> Reply | None:
        """Robot ``name``'s bridge route ``rest`` (its page is at ``home``)."""
        if not slash:  # /robot1: the page's relative links need /robot1/
            return _redirect(home, query)
        if self.access.security.auth is not None:
            # Without a token, every robot's routes answer alike, known or not (no name can
            # be found out): the page's own files are the same for all, the rest is 401.
            page = "/static/index.html" if not rest else "/" + rest
            if page.startswith("/static/"):
                return open_route(page, self._static, self.relay.trouble)
            _, refusal = viewer(WebAccess(self.access.security, robot=name), request, address,
                                "/status.json")
            if refusal is not None:
                return refusal
        bridge = await self.relay.robot(name)
        if bridge is None:
            return Reply(404, f"no robot named {name!r} is connected to this relay's Zenoh "
                         "network\n".encode())
        inner = type(request)("/" + rest + (f"?{query}" if query else ""), request.headers)
        reply = await bridge.web.answer(inner, address)
        if rest == "status.json" and reply is not None and reply.status == 200:
            reply = self._named(reply, name)
        return reply

    def _named(self, reply: Reply, name: str) -> Reply:
        """A robot's ``status.json`` as the relay serves it, naming the robot and the relay
        (its page's title, and the relay's process apart from the robot's nodes)."""
        data = json.loads(reply.body)
        data["robot"] = name
        data["relay"] = {"id": self.relay.relay_id, "pid": os.getpid(), "started": self.started}
        return Reply(200, json.dumps(data, separators=(",", ":")).encode(), reply.content_type,
                     reply.headers)

    async def _own(self, path: str, request: Request, address: str) -> Reply | None:
        if path == "/":
            path = "/static/relay.html"
        reply = open_route(path, self._static, self.relay.trouble)
        if reply is not None or path.startswith("/static/"):
            return reply
        principal, refusal = viewer(self.access, request, address, path)
        if refusal is not None:
            return refusal
        nocache = [("Cache-Control", "no-store")]
        snaps = {name: visible(bridge.web.local(), principal, bridge.web.access)
                 for name, bridge in sorted(self.relay.robots.items())
                 if self.access.may_reach(principal, name)}
        online = {name for name in await self.relay.on_network()
                  if self.access.may_reach(principal, name)}
        robots = self._robots(snaps, online)
        self.rates.add(time.monotonic(), {r.name: tuple(float(getattr(r, f)) for f in _RATED)
                                          for r in robots})
        if path == "/status.json":
            data = self._status(robots)
            data["names_refused"] = {name: entry for name, entry
                                     in sorted(self.relay.names_refused.items())
                                     if self.access.may_reach(principal, name)}
            data["robots_refused"] = robots_refused(
                self.relay.robots_refused(), lambda name: self.access.may_reach(principal, name))
            return Reply(200, json.dumps(data, separators=(",", ":")).encode(),
                         "application/json", nocache)
        refused = CounterMetricFamily(
            "roslibpy_relay_connections_refused",
            "Clients the relay turned away before any robot's bridge saw them, by reason "
            "(no_router, unknown_robot, no_robot_named, invalid_robot_name, robot_not_allowed, "
            "auth, origin, too_many, max_clients).", labels=["reason"])
        for reason, n in sorted(self.relay.refused.items()):
            refused.add_metric([reason], n)
        names = CounterMetricFamily(
            "roslibpy_relay_robot_names_refused",
            "Robots refused a name another robot held (one robot per name), by the name.",
            labels=["robot"])
        for name, entry in sorted(self.relay.names_refused.items()):
            if self.access.may_reach(principal, name):
                names.add_metric([name], entry["count"])
        body = metrics.render_labelled(
            ((name, snap, self.relay.robots[name].web.caps) for name, snap in snaps.items()),
            "robot", [*robot_families(robots), refused, names,
                      robots_refused_family(self.relay.robots_refused())])
        return Reply(200, body, metrics.CONTENT_TYPE, nocache)

    def _present(self, name: str, online: set[str]) -> bool:
        bridge = self.relay.robots.get(name)
        if bridge is not None:  # followed: its liveliness subscriber knows at once
            return bridge.graph.trouble() is None
        return name in online

    def _robots(self, snaps: Mapping[str, Mapping[str, Any]], online: set[str]
                ) -> list[RobotStatus]:
        """The robots on Zenoh or served, with their bridges' (visible) snapshots."""
        robots = []
        for name in sorted(online | set(snaps)):
            bridge = self.relay.robots.get(name) if name in snaps else None  # served
            robots.append(robot_status(
                name, present=self._present(name, online), snap=snaps.get(name),
                bytes_from_robot=_bytes_from_robot(bridge) if bridge is not None else 0,
                dropped=_dropped(bridge) if bridge is not None else {}))
        return robots

    def _status(self, robots: list[RobotStatus]) -> dict[str, Any]:
        from rosbridge_core import __version__

        rates = self.rates.rates()  # every robot's, once a page
        return {"relay": self.relay.relay_id, "version": __version__, "started": self.started,
                "now": time.time(), "ready": self.relay.trouble() is None,
                "refused": dict(self.relay.refused), "rate_window_s": RATE_WINDOW,
                "forgotten": self.relay.forgetter.forgotten,
                "forgetting": self.relay.forgetter.closing,
                "robots": [_with_rates(robot, rates) for robot in robots]}


def _with_rates(robot: RobotStatus, rates: Mapping[str, tuple[float, ...]]) -> dict[str, Any]:
    """A robot's entry, with ``<counter>_per_s`` over :data:`RATE_WINDOW` in ``rates``
    (``rates``: every robot's, taken once a page: taken per robot, a page of 500 robots took
    1-3 s; sampled as viewers ask: none before a second reading)."""
    per_s = rates.get(robot.name, ())
    entry = robot.to_json()
    entry["rates"] = {f"{f}_per_s": round(r, 1) for f, r in zip(_RATED, per_s, strict=False)}
    return entry


_RATED = ("messages_from_robot", "bytes_from_robot", "messages_to_clients", "bytes_to_clients",
          "messages_from_clients", "bytes_from_clients")
"""A robot's counters the relay's page gives a rate of."""


def _redirect(to: str, query: str) -> Reply:
    """308 to ``to``, the query string (a ``?token=``) kept."""
    return Reply(308, b"", headers=[("Location", to + (f"?{query}" if query else ""))])


def _bytes_from_robot(bridge: Bridge) -> int:
    """Payload bytes of the robot's topic messages as the relay received them from Zenoh
    (counted by its :class:`~bridge_server.zenoh.graph.ZenohGraph`; 0 for another graph)."""
    return int(getattr(bridge.graph, "received_bytes", 0))


def _dropped(bridge: Bridge) -> dict[str, int]:
    """What the robot sent that its :class:`~bridge_server.zenoh.graph.ZenohGraph` dropped,
    by kind (:class:`~bridge_server.zenoh.inbox.Faults`; empty for another graph)."""
    faults = getattr(bridge.graph, "faults", None)
    return dict(faults.counts) if faults is not None else {}
