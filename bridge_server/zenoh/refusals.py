"""Robots a relay's router did not admit, said where the operator looks (issue 50, item 1).

A relay that is the Zenoh router with ``--zenoh-mtls`` refuses a robot in one of two
places, and neither told the operator before:

* at the TLS handshake (no certificate, one from another CA, one without the
  ``clientAuth`` key usage): Zenoh logged ``peer sent no certificates. Hint: increase the
  system open file limit.`` once a second, with no address and a wrong hint;
* by its access rules, silently: a certificate whose common name is not in
  ``--zenoh-robot`` (a link comes, its messages are dropped), or a robot announcing itself
  under a name its certificate is not for (another robot's certificate).

:class:`RobotRefusals` hears both (Zenoh's log lines through
:mod:`~bridge_server.zenoh.zenoh_logpipe`; the router's link events) and logs one WARNING per
robot, address and reason a minute (with how many more meanwhile), naming the robot where
known, the peer address and the reason with what to fix; it counts each refusal by reason
(the relay's ``/status.json`` and ``/metrics``) and remembers the last one of each robot
name, so a client asking for that robot is told it was refused and why (404), not that it is
not connected. Zenoh's ``Unknown token id=N`` (``Unknown id``, ``Unknown interest``, ...)
errors when a refused robot leaves (one per declaration its access rules dropped) are not
shown.
"""

from __future__ import annotations

import contextlib
import logging
import re
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bridge_server.zenoh import keys

if TYPE_CHECKING:
    import zenoh

__all__ = ["REASONS", "ZENOH_LOG", "Refusal", "RobotRefusals", "reading_zenoh_log"]

log = logging.getLogger("bridge_server.relay")

ZENOH_LOG = ("error,zenoh_link_tls=warn,"
             "zenoh::net::routing::interceptor::access_control=trace")
"""Zenoh's log as a relay reads it (unless ``RUST_LOG`` says otherwise): errors, the TLS
refusals, and the access rules' decisions (one line per session and key expression, not per
message), from which a robot under another certificate's name is known."""

REPEAT = 60.0
"""Seconds between two WARNINGs of one robot, address and reason (each refusal is counted)."""

UNPLACED = "an address Zenoh does not give"
"""The peer of a TLS refusal whose connection was gone when its line was read."""

PLACE_TRIES = 3
"""TLS refusals of one reason in a row whose address was gone (the connection closed before
its line was read) before the WARNING is logged without the address."""

LINKS_KEPT = 1024
"""Recent links remembered (Zenoh id -> certificate name and address) for the access
rules' lines, which name a session by its Zenoh id only."""

REASONS = {
    "not_named": "its certificate's name is not in --zenoh-robot",
    "other_name": "its certificate is for another robot",
    "no_certificate": "it gave no certificate",
    "unknown_ca": "its certificate is not signed by --zenoh-tls-ca",
    "key_usage": "its certificate's key usage does not allow a client",
    "tls_refused": "its TLS handshake failed",
}
"""Each reason a robot is refused (the ``reason`` label), and what it means."""

_TLS = re.compile(r"zenoh_link_tls::unicast: (?P<what>.*?)\. Hint: increase the system open "
                  r"file limit\.$")
_DENIED = re.compile(r"access_control: (?:Using cached result: )?(?P<zid>[0-9a-f]+)"
                     r"(?: on \S+)? is unauthorized to Liveliness Token \(ingress\) on "
                     rf"(?P<robot>[^/\s]+)/{re.escape(keys.ALIVE)}/")
_ACL = re.compile(r"^\S+\s+(?:TRACE|DEBUG|INFO) .*zenoh::net::routing::interceptor::"
                  r"access_control: ")
"""The access rules' lines below a warning: read, not shown (a warning or error is)."""
_UNKNOWN_TOKEN = re.compile(r"ERROR .*zenoh::net::routing::hat::\S+: Unknown "
                            r"(?:id|interest|token|subscriber|queryable)\b")
"""A session undeclaring what the access rules dropped (a refused robot leaving): one line
per declaration, nothing an operator acts on."""
_CERT_NAME = re.compile(r"access_control: (?P<zid>[0-9a-f]+) on "
                        r"\S*CertCommonName\((?P<name>[^)]+)\)")
_TCP_STATES = {"01", "04", "05", "06", "07", "08", "09", "0B"}
"""/proc/net/tcp states of a connection open or being closed (ESTABLISHED, FIN_WAIT1 ..
CLOSING; TIME_WAIT lasts a minute)."""


@dataclass
class Refusal:
    """The last refusal of one robot name (or of one address, name unknown)."""

    reason: str
    text: str
    """Why, with what to fix."""
    peer: str
    count: int = 0
    last: float = 0.0
    logged: float = 0.0
    """When the last WARNING was (``time.monotonic()``)."""
    unlogged: int = 0
    """Refusals since the last WARNING."""

    def to_json(self) -> dict[str, Any]:
        """Its entry in ``/status.json``."""
        return {"reason": self.reason, "why": self.text, "peer": self.peer,
                "count": self.count, "last": self.last}


class RobotRefusals:
    """The robots refused by this relay's router (thread-safe: Zenoh's threads and the
    stderr reader report here)."""

    def __init__(self, robots: Sequence[str], relays: Sequence[str],
                 listen: Sequence[str] = ()) -> None:
        self.robots = set(robots)
        self.relays = set(relays)
        self.ports = {_port(e) for e in listen} - {None}
        self.counts: dict[str, int] = {}
        """Refusals by reason."""
        self.by_robot: dict[str, Refusal] = {}
        self._by_peer: dict[tuple[str, str, str], Refusal] = {}
        self._links: OrderedDict[str, tuple[str | None, str]] = OrderedDict()
        self._names: OrderedDict[str, str] = OrderedDict()
        """Zenoh id -> certificate name, as the access rules' lines give it."""
        self._pending: dict[str, str] = {}
        """Zenoh id -> the robot name its presence was refused, until its link is known."""
        self._unplaced: dict[str, int] = {}
        """TLS refusals by reason whose address was gone when their line came."""
        self._open: set[str] = set()
        """``host:port`` of the router's links open now (admitted at the handshake)."""
        self._lock = threading.Lock()
        self.unknown_tokens = 0
        """Zenoh's ``Unknown token`` (id, interest, ...) errors not shown."""
        self._unknown_told = -REPEAT

    def refuse(self, reason: str, robot: str | None, peer: str, text: str, told: bool = True
               ) -> None:
        """Count a refusal; log it (``told``) unless the same one was logged within
        :data:`REPEAT`."""
        now, wall = time.monotonic(), time.time()
        with self._lock:
            self.counts[reason] = self.counts.get(reason, 0) + 1
            key = (reason, robot or "", _host(peer) if robot else "")
            entry = self._by_peer.get(key)
            if entry is None:
                entry = self._by_peer[key] = Refusal(reason, text, peer)
            entry.text, entry.peer = text, peer or entry.peer
            entry.count += 1
            entry.last = wall
            if robot is not None:
                self.by_robot[robot] = entry
            if not told or (entry.logged and now - entry.logged < REPEAT):
                entry.unlogged += 1 if entry.logged else 0
                return
            again = f" ({entry.unlogged} more since the last such line)" if entry.unlogged else ""
            entry.logged, entry.unlogged = now, 0
        who = f"robot {robot}" if robot else "a robot (name unknown: no verified certificate)"
        log.warning("refused %s at %s: %s%s", who, peer, text, again)

    def why(self, robot: str) -> str | None:
        """What a client asking for ``robot`` is told if this relay refused it (``None``:
        it did not)."""
        with self._lock:
            entry = self.by_robot.get(robot)
        if entry is None:
            return None
        when = time.strftime("%H:%M:%S UTC", time.gmtime(entry.last))
        return (f"robot {robot!r} was refused by this relay: {entry.text} (last at {when}, "
                f"from {entry.peer}, {entry.count} times)")

    def snapshot(self) -> dict[str, Any]:
        """Counts by reason and the last refusal of each robot name (``/status.json``)."""
        with self._lock:
            return {"counts": dict(self.counts),
                    "robots": {name: e.to_json() for name, e in sorted(self.by_robot.items())}}

    # -- the router's links ------------------------------------------------------------

    def on_link(self, event: zenoh.LinkEvent) -> None:
        """A link came (or went): one whose certificate names no robot or relay of
        ``--zenoh-robot``/``--zenoh-relay`` is refused by the access rules."""
        import zenoh

        link = event.link
        name, peer, zid = link.auth_identifier, str(link.dst), str(link.zid).lstrip("0")
        if event.kind != zenoh.SampleKind.PUT:
            with self._lock:
                self._open.discard(peer.rpartition("/")[2])
            return
        with self._lock:
            self._open.add(peer.rpartition("/")[2])
            _keep(self._links, zid, (name, peer))
            robot = self._pending.pop(zid, None)
        if robot is not None:
            self._denied(zid, robot)
        if name and name not in self.robots and name not in self.relays:
            self.refuse("not_named", name, peer,
                        f"it is not in --zenoh-robot (add --zenoh-robot {name} to this relay; "
                        f"--zenoh-relay {name} if it is a relay)")

    # -- Zenoh's log ------------------------------------------------------------------

    def on_line(self, line: str) -> str | None:
        """A line of Zenoh's log (:func:`~.zenoh_logpipe.filter_zenoh_log`): a refusal is told
        as such, the access rules' trace and ``Unknown token`` errors are not shown, any
        other line is passed on."""
        m = _TLS.search(line)
        if m is not None:
            self._tls(m["what"])
            return None
        if _ACL.search(line) is not None:
            named = _CERT_NAME.search(line)
            if named is not None:
                with self._lock:
                    _keep(self._names, named["zid"].lstrip("0"), named["name"])
            denied = _DENIED.search(line)
            if denied is not None:
                self._denied(denied["zid"], denied["robot"])
            return None
        if _UNKNOWN_TOKEN.search(line) is not None:
            self.unknown_tokens += 1
            now = time.monotonic()
            if now - self._unknown_told >= REPEAT:
                self._unknown_told = now
                log.debug("Zenoh's 'Unknown ...' errors (%d so far) not shown: a session "
                          "undeclaring what the access rules dropped", self.unknown_tokens)
            return None
        return line

    def _tls(self, what: str) -> None:
        if what == "peer sent no certificates":
            reason, text = ("no_certificate", "it gave no certificate (give the robot "
                            "--zenoh-tls-cert and --zenoh-tls-key: 'roslibpy-lite-relay certs "
                            "--robot NAME' makes them)")
        elif "UnknownIssuer" in what or "BadSignature" in what:
            reason, text = ("unknown_ca", f"its certificate is not signed by this relay's "
                            f"--zenoh-tls-ca ({what}): give it a certificate from this fleet's CA")
        elif "extended key usage" in what:
            reason, text = ("key_usage", f"its certificate's key usage does not allow a client "
                            f"({what}): a robot's certificate needs clientAuth "
                            "('roslibpy-lite-relay certs --robot NAME' makes one)")
        else:
            reason, text = "tls_refused", f"its TLS handshake failed: {what}"
        peer = self._closing_peer()
        if peer is None:  # closed already: the robot dials again within a second
            with self._lock:
                unplaced = self._unplaced[reason] = self._unplaced.get(reason, 0) + 1
            if unplaced < PLACE_TRIES:
                self.refuse(reason, None, "", text, told=False)
                return
            peer = UNPLACED
        with self._lock:
            self._unplaced[reason] = 0
        self.refuse(reason, None, peer, text)

    def _denied(self, zid: str, robot: str) -> None:
        """The access rules dropped a presence token of ``robot`` from session ``zid``."""
        zid = zid.lstrip("0")
        with self._lock:
            link = self._links.get(zid)
            if link is None:  # its link event comes after this line: on_link calls again
                self._pending[zid] = robot
                while len(self._pending) > LINKS_KEPT:
                    self._pending.pop(next(iter(self._pending)))
                return
            name, peer = link
            name = name or self._names.get(zid)
        if name is None or name not in self.robots or name == robot:
            return  # not named at all: on_link told it
        self.refuse("other_name", robot, peer,
                    f"its certificate is for {name!r}, not {robot!r} (give it robot "
                    f"{robot}'s certificate, or run it as --robot {name})")

    def _closing_peer(self) -> str | None:
        """The address a TLS handshake just failed from, as the kernel lists it: Zenoh's
        line names none (at any log level). Over a network the router closes first, and the
        connection stays listed a minute (TIME_WAIT); over loopback the robot may close first
        and nothing stays: :data:`PLACE_TRIES`. The hosts of connections to a listening
        port, open (not an admitted link) or being closed now."""
        hosts: set[str] = set()
        for table, v6 in (("/proc/net/tcp", False), ("/proc/net/tcp6", True)):
            with contextlib.suppress(OSError), open(table, encoding="ascii") as f:
                next(f, None)
                for row in f:
                    cols = row.split()
                    local, remote, state = cols[1], cols[2], cols[3]
                    mine = int(local.rsplit(":", 1)[1], 16) in self.ports
                    if state not in _TCP_STATES or not mine:
                        continue
                    host, port = _address(remote.rsplit(":", 1)[0], v6), int(remote[-4:], 16)
                    with self._lock:
                        admitted = f"{host}:{port}" in self._open
                    if not admitted:
                        hosts.add(host)
        if not hosts:
            return None
        if len(hosts) == 1:
            return next(iter(hosts))
        return "one of " + ", ".join(sorted(hosts)[:4])


def reading_zenoh_log(robots: Sequence[str], relays: Sequence[str], listen: Sequence[str]
                      ) -> RobotRefusals:
    """The refusals of a relay that is its robots' router with mTLS, heard in Zenoh's log
    (:data:`ZENOH_LOG` unless ``RUST_LOG`` is set) from the session's opening on."""
    import os

    from bridge_server.zenoh.zenoh_logpipe import filter_zenoh_log

    refusals = RobotRefusals(robots, relays, listen)
    os.environ.setdefault("RUST_LOG", ZENOH_LOG)
    filter_zenoh_log(refusals.on_line)
    return refusals


def _keep(recent: OrderedDict[str, Any], key: str, value: Any) -> None:
    """``recent[key] = value``, the oldest forgotten past :data:`LINKS_KEPT`."""
    recent[key] = value
    recent.move_to_end(key)
    while len(recent) > LINKS_KEPT:
        recent.popitem(last=False)


def _port(endpoint: str) -> int | None:
    with contextlib.suppress(ValueError):
        return int(endpoint.partition("#")[0].rsplit(":", 1)[1])
    return None


def _host(peer: str) -> str:
    """``tls/127.0.0.1:40756`` -> ``127.0.0.1`` (a robot dials from a new port each time)."""
    return peer.rpartition("/")[2].rpartition(":")[0] or peer


def _address(hexed: str, v6: bool) -> str:
    """An address of /proc/net/tcp (little-endian 32-bit words in hex)."""
    import ipaddress

    raw = bytes.fromhex(hexed)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    ip = ipaddress.ip_address(words)
    if v6 and isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        return str(ip.ipv4_mapped)
    return str(ip)
