"""Opening the Zenoh session of a robot's exporter or of a relay, from command-line options.

``zenoh`` is imported when a session is opened, not with this module, so the bridge's
command line parses where it is not installed.

The robot and a relay that uses routers are Zenoh clients (``--zenoh-connect``: they dial
out, nothing dials in); a relay with ``--zenoh-listen`` is itself a router in-process.
Multicast scouting is off: who talks to whom is what the options say, nothing found on
the LAN. A client waits for its router as long as it takes (the session opens in a thread,
so the event loop goes on), and Zenoh reconnects it by itself if the link drops.

Every link can be TLS, and a router can ask each side for a certificate
(``--zenoh-mtls``): then a robot proves who it is by its certificate's common name, and
the router lets it use only the keys under that name (:func:`robot_acl`), so no robot can
publish, serve or answer as another. Relays, named by their certificates too
(``--zenoh-relay``), hear every robot's keys but send only what a relay's role needs (its
requests, under its own name where a key names a relay; a client's message to publish under
``@in/``): never a robot's topic data, graph, replies or presence. A router asking for
certificates always has these rules: one naming nobody refuses to start
(:data:`UNNAMED_MTLS`). Which viewer may reach which robot is the relay's roles' business
(``robots = [...]`` in a role).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import re
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bridge_server.zenoh import keys
from rosbridge_core.interfaces import BridgeError

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger("bridge_server.zenoh.link")

__all__ = ["UNNAMED_MTLS", "ZenohOptions", "add_arguments", "answering", "ignore_replies",
           "open_session", "options_from_args", "robot_acl", "tokens"]

_PROTOCOLS = ("tcp", "tls", "quic", "udp", "unixsock-stream")
_ENDPOINT = re.compile(r"(?P<proto>[a-z-]+)/(?P<addr>[^#?]+)(?:[#?].*)?")
_CONTROL = keys.CONTROL
"""The robot's control chunks: Zenoh's verbatim chunks, which no wildcard matches, so the
access rules name each."""
# Everything a robot does on its own keys: puts its topics, declares its queryables and
# answers them, holds its liveliness token, follows the relays' tokens, takes their puts.
_MESSAGES = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
             "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]


UNNAMED_MTLS = (
    "--zenoh-mtls names nobody: give --zenoh-robot NAME for each robot (its certificate's "
    "common name; it may then use the keys under that name only) and --zenoh-relay NAME for "
    "each other relay that connects. Without them every certificate the CA signed could act "
    "as any robot or relay (Zenoh's access rules match certificates by exact common name, "
    "so the rules cannot be made from the certificates alone)")
"""Why a router asking for certificates must name who may come in: it refuses to start
rather than run without access rules."""

_LOOPBACK = re.compile(r"(?:127(?:\.\d{1,3}){3}|localhost|\[?::1\]?)")


def _host(endpoint: str) -> str:
    """The host of ``PROTO/HOST:PORT`` (an IPv6 address keeps its brackets)."""
    m = _ENDPOINT.fullmatch(endpoint)
    return (m["addr"] if m else endpoint).rpartition(":")[0]


def _local(endpoint: str) -> bool:
    """Whether ``endpoint`` stays on this machine: loopback, or a unix socket."""
    return endpoint.startswith("unixsock-stream/") or bool(_LOOPBACK.fullmatch(_host(endpoint)))


def _tls(endpoint: str) -> bool:
    """Whether ``endpoint``'s protocol is TLS (tls/, or quic/, which is TLS too)."""
    return endpoint.startswith(("tls/", "quic/"))


def _under(prefix: str) -> list[str]:
    return [f"{prefix}/**", *(f"{prefix}/{c}" for c in _CONTROL),
            *(f"{prefix}/{c}/**" for c in _CONTROL), f"{prefix}/**/{keys.ADV}/**"]


def robot_acl(robots: Sequence[str], relays: Sequence[str]) -> dict[str, Any]:
    """A router's access control: each robot (by its certificate's common name, which is its
    robot name) only on keys under its name; each relay (by its certificate's common name,
    which is its relay id) hears every robot's keys but sends only what its role needs
    (:func:`_relay_grants`); anyone else on nothing."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def allow(subject: str, names: list[str],
              *grants: tuple[list[str], list[str], list[str]]) -> None:
        """``names`` may use each grant's (key expressions, messages, flows)."""
        ids = [f"{subject}.{n}" for n in range(len(grants))]
        for rule, (key_exprs, messages, flows) in zip(ids, grants, strict=True):
            rules.append({"id": rule, "messages": messages, "flows": flows,
                          "permission": "allow", "key_exprs": key_exprs})
        subjects.append({"id": subject, "cert_common_names": names})
        policies.append({"rules": ids, "subjects": [subject]})

    for i, robot in enumerate(robots):
        allow(f"robot{i}", [robot], ([robot, *_under(robot)], _MESSAGES, ["ingress", "egress"]))
    for i, relay in enumerate(relays):
        allow(f"relay{i}", [relay], *_relay_grants(relay))
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def _relay_grants(relay: str) -> list[tuple[list[str], list[str], list[str]]]:
    """What relay ``relay`` may do on robots' keys, as (key expressions, messages, flows).

    It hears everything of every robot (egress: topics, graph documents, replies, tokens,
    the robot's queries of its clients' services). What it sends (ingress) is only what its
    role needs: under its own name only (the chunk after :data:`keys.RELAY_TOKENS`,
    :data:`keys.RELAY_ASKS`, :data:`keys.RELAY_ANSWERS`) its tokens, calls, goals and
    cancels, and its clients' served names' queryables and their replies; the queries that
    name no relay (:data:`keys.ROBOT_ANSWERS`: graph, latched messages, parameters; a
    reliable topic's cache); its subscriptions; and puts under :data:`keys.RELAY_PUTS`
    (``@in/``) alone: a client's message to publish travels as a put there, which the robot
    publishes in ROS. Never topic data, a graph document, a reply or presence under a
    robot's keys.
    """
    def scoped(chunks: tuple[str, ...]) -> list[str]:
        return [f"*/{c}/{relay}/**" for c in chunks]

    adv = f"**/{keys.ADV}/**"  # a reliable topic's cache and its tokens (zenoh.ext's keys)
    everything = ["**", *(k for c in _CONTROL for k in (f"*/{c}", f"*/{c}/**")), adv]
    asked = [*(k for c in keys.ROBOT_ANSWERS for k in (f"*/{c}", f"*/{c}/**")), adv,
             *scoped(keys.RELAY_ASKS)]
    hears = ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"]
    return [
        (everything, _MESSAGES, ["egress"]),
        (everything, hears, ["ingress"]),
        ([f"*/{c}/**" for c in keys.RELAY_PUTS], ["put"], ["ingress"]),
        (asked, ["query"], ["ingress"]),
        (scoped(keys.RELAY_ANSWERS), ["declare_queryable", "reply"], ["ingress"]),
        (scoped(keys.RELAY_TOKENS), ["liveliness_token"], ["ingress"]),
    ]


@dataclass
class ZenohOptions:
    """Where the session connects or listens, its TLS files, and (a router) who may come in."""

    connect: list[str] = field(default_factory=list)
    listen: list[str] = field(default_factory=list)
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None
    mtls: bool = False
    """A listener asks whoever connects for a certificate signed by ``tls_ca``."""
    robots: list[str] = field(default_factory=list)
    """With ``mtls``: robots let in by their certificates' common names, each on its keys."""
    relays: list[str] = field(default_factory=list)
    """With ``mtls``: relays let in by their certificates' common names, on every robot's
    keys (those naming a relay: under their own name only)."""
    lease: float = 3.0
    """Seconds of silence after which a link counts as dead (Zenoh's lease; each side sends
    keep-alives four times per lease): the robot's liveliness goes, and its clients are told."""
    insecure: bool = False
    """Allow links beyond this machine without (mutual) TLS (:meth:`exposure` says what
    that exposes; logged as a warning when the session opens)."""

    def exposure(self) -> str | None:
        """What these options expose beyond this machine (``None``: nothing).

        A router listening on an address other than loopback without mutual TLS lets
        anyone who reaches it pose as any robot, or, through a relay of their own, call
        every robot's services and publish on its topics; a client dialing beyond loopback
        without TLS sends everything in clear to whoever answers."""
        for e in self.listen:
            if not _local(e) and not (self.mtls and _tls(e)):
                return (f"--zenoh-listen {e} listens beyond this machine without mutual TLS: "
                        "anyone who reaches it can pose as a robot, or drive one through a "
                        "relay of their own")
        for e in self.connect:
            if not _local(e) and not _tls(e):
                return (f"--zenoh-connect {e} dials beyond this machine without TLS: the "
                        "link is in clear and anyone on the way can pose as the router")
        return None

    def refusal(self) -> str | None:
        """Why these options must not start (their :meth:`exposure`, without
        ``--zenoh-insecure``), naming what to do instead; ``None``: they may."""
        exposed = self.exposure()
        if exposed is None or self.insecure:
            return None
        return (f"{exposed}. Use tls/ endpoints with certificates (a router: --zenoh-mtls "
                "and --zenoh-tls-ca/-cert/-key; a robot: --zenoh-tls-ca/-cert/-key; "
                "'roslibpy-lite-relay certs' makes them), or give --zenoh-insecure to accept "
                "that")

    @property
    def mode(self) -> str:
        """``router`` when it listens, else ``client``."""
        return "router" if self.listen else "client"

    def config(self) -> zenoh.Config:
        """The Zenoh configuration; ``BridgeError`` naming an option that does not fit."""
        import zenoh

        if not self.connect and not self.listen:
            raise BridgeError("no Zenoh endpoint: give --zenoh-connect or --zenoh-listen")
        for option, endpoints in (("--zenoh-connect", self.connect),
                                  ("--zenoh-listen", self.listen)):
            for e in endpoints:
                m = _ENDPOINT.fullmatch(e)
                if m is None or m["proto"] not in _PROTOCOLS or (
                        ":" not in m["addr"] and m["proto"] != "unixsock-stream"):
                    raise BridgeError(
                        f"{option} {e!r}: not a Zenoh endpoint (PROTOCOL/HOST:PORT, protocol "
                        f"one of {', '.join(_PROTOCOLS)}; for example tls/relay.example.com:7447)")
        for what, path in (("--zenoh-tls-ca", self.tls_ca), ("--zenoh-tls-cert", self.tls_cert),
                           ("--zenoh-tls-key", self.tls_key)):
            if path is not None and not os.access(path, os.R_OK):
                raise BridgeError(f"{what} {path}: not a readable file")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise BridgeError("--zenoh-tls-cert and --zenoh-tls-key go together")
        uses_tls = any(_tls(e) for e in [*self.connect, *self.listen])
        if uses_tls and self.listen and self.tls_cert is None:
            raise BridgeError("a tls/ or quic/ --zenoh-listen endpoint needs --zenoh-tls-cert "
                              "and --zenoh-tls-key")
        if self.tls_ca is None and any(_tls(e) for e in self.connect):
            raise BridgeError("a tls/ or quic/ --zenoh-connect endpoint needs --zenoh-tls-ca "
                              "(the authority that signs the router's certificate)")
        if self.mtls and not (self.listen and uses_tls and self.tls_ca is not None):
            raise BridgeError("--zenoh-mtls asks those who connect for certificates signed by "
                              "--zenoh-tls-ca: it needs that and a tls/ --zenoh-listen endpoint")
        if (self.robots or self.relays) and not self.mtls:
            raise BridgeError("--zenoh-robot/--zenoh-relay name certificates: they need "
                              "--zenoh-mtls")
        if self.mtls and not (self.robots or self.relays):
            raise BridgeError(UNNAMED_MTLS)
        for robot in self.robots:
            try:
                keys.check_robot(robot)
            except BridgeError as exc:
                raise BridgeError(f"--zenoh-robot: {exc}") from None
        refusal = self.refusal()
        if refusal is not None:
            raise BridgeError(refusal)
        if not 0.1 <= self.lease <= 3600:
            raise BridgeError(f"--zenoh-lease {self.lease:g}: expected 0.1 to 3600 seconds")
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(self.mode))
        conf.insert_json5("transport/link/tx/lease", json.dumps(round(self.lease * 1000)))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("scouting/gossip/enabled", "false" if not self.listen else "true")
        conf.insert_json5("connect/endpoints", json.dumps(self.connect))
        conf.insert_json5("listen/endpoints", json.dumps(self.listen))
        if self.listen:
            conf.insert_json5("transport/unicast/max_sessions", json.dumps(ROUTER_SESSIONS))
        # Robots and relays meet over networks: Zenoh's shared memory between processes of
        # one machine (its default for payloads over ~3 KB) would bypass the link and its
        # TLS, so the link carries everything here too.
        conf.insert_json5("transport/shared_memory/enabled", "false")
        # a client waits for its routers (in open_session's thread) instead of failing
        conf.insert_json5("connect/timeout_ms", json.dumps({"client": -1, "router": 0}))
        # a client whose link dropped dials again each second at most (Zenoh's default
        # backs off to 4 s): a robot's outage ends, and its replay window drains, that much
        # sooner once the link is back (a 15 s veth cut: 1.5 s to recover instead of 4.4 s)
        conf.insert_json5("connect/retry", json.dumps(
            {"period_init_ms": 500, "period_max_ms": 1000, "period_increase_factor": 2}))
        tls = "transport/link/tls"
        if self.tls_ca is not None:
            conf.insert_json5(f"{tls}/root_ca_certificate", json.dumps(self.tls_ca))
        if self.tls_cert is not None and self.tls_key is not None:
            side = "listen" if self.listen else "connect"
            conf.insert_json5(f"{tls}/{side}_certificate", json.dumps(self.tls_cert))
            conf.insert_json5(f"{tls}/{side}_private_key", json.dumps(self.tls_key))
        # Zenoh shows this side's certificate to a listener only with mTLS on (one switch for
        # both ways): a client with a certificate turns it on, a router when told to.
        if self.mtls or (not self.listen and self.tls_cert is not None):
            conf.insert_json5(f"{tls}/enable_mtls", "true")
        if self.mtls:  # never without rules: config() refused mutual TLS naming nobody
            conf.insert_json5("access_control", json.dumps(robot_acl(self.robots, self.relays)))
        return conf


ROUTER_SESSIONS = 10_000
"""Sessions a router of ours takes at once (robots, relays and other routers; Zenoh's
``transport/unicast/max_sessions``). Zenoh's own default, 1,000, refused the 1,001st robot
of a fleet on one router with nothing in the router's log and only "close (reason INVALID)"
in the robot's. A robot's session costs its router about 130 KiB: 10,000 are some 1.3 GB."""

ZENOH_LOG = "error,zenoh_link_tls=warn"
"""What of Zenoh's own log (written by Zenoh to standard output, descriptor 1: see
:mod:`.zenoh_logpipe`) a process shows unless ``RUST_LOG``
says otherwise: errors, and why a TLS link was refused (a certificate from another CA, or
without the key usage its side needs), which nothing else tells."""

_zenoh_log_on = False


def _zenoh_log() -> None:
    """Turn Zenoh's own log on, once per process (plain text where stderr is no terminal)."""
    global _zenoh_log_on
    if _zenoh_log_on:
        return
    import sys

    import zenoh

    _zenoh_log_on = True
    if not sys.stderr.isatty():
        os.environ.setdefault("NO_COLOR", "1")
    with contextlib.suppress(Exception):  # another part of the process set it up first
        zenoh.init_log_from_env_or(ZENOH_LOG)


async def open_session(options: ZenohOptions) -> zenoh.Session:
    """Open the session in a thread of its own (a client waits there until a router
    answers); cancelled meanwhile, the session is closed as soon as it opens. The thread is a
    daemon: a process told to stop while no router answered exits without waiting for it."""
    import zenoh

    conf = options.config()
    _zenoh_log()
    exposed = options.exposure()
    if exposed is not None:  # config() allowed it: --zenoh-insecure
        log.warning("--zenoh-insecure: %s", exposed)
    loop = asyncio.get_running_loop()
    opened: asyncio.Future[zenoh.Session] = loop.create_future()

    def deliver(session: zenoh.Session | None, exc: BaseException | None) -> None:
        if opened.done():  # nobody waits any more
            if session is not None:
                threading.Thread(target=session.close, daemon=True).start()
        elif exc is not None:
            opened.set_exception(BridgeError(f"cannot open the Zenoh session: {exc}"))
        else:
            opened.set_result(session)  # type: ignore[arg-type]

    def open_it() -> None:
        try:
            session = zenoh.open(conf)
        except zenoh.ZError as exc:
            loop.call_soon_threadsafe(deliver, None, exc)
            return
        try:
            loop.call_soon_threadsafe(deliver, session, None)
        except RuntimeError:  # the loop is closed: the process is stopping
            session.close()  # type: ignore[no-untyped-call]

    threading.Thread(target=open_it, daemon=True, name="zenoh-open").start()
    return await opened


async def tokens(session: zenoh.Session, key: str, timeout: float, first: bool = False
                 ) -> set[str]:
    """The keys of the liveliness tokens matching ``key`` on the network now (with
    ``first``, as soon as one answers; at most ``timeout`` s)."""

    loop = asyncio.get_running_loop()
    done: asyncio.Future[None] = loop.create_future()
    found: set[str] = set()

    def seen(key: str) -> None:
        found.add(key)
        if first and not done.done():
            done.set_result(None)

    def ended() -> None:
        if not done.done():
            done.set_result(None)

    def reply(r: zenoh.Reply) -> None:
        if r.ok is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(seen, str(r.ok.key_expr))

    def end() -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(ended)

    from bridge_server.zenoh.inbox import direct

    session.liveliness().get(key, direct(reply, end), timeout=timeout)
    await done
    return found


@contextlib.contextmanager
def answering(query: zenoh.Query) -> Iterator[None]:
    """Finish ``query`` when the block ends (the querier hears "no more replies")."""
    try:
        yield
    finally:
        query.drop()  # type: ignore[no-untyped-call]


def ignore_replies(_reply: zenoh.Reply) -> None:
    """For a query whose replies say nothing (a cancel: its answer comes another way)."""


def add_arguments(p: argparse.ArgumentParser, listen: bool) -> None:
    """The Zenoh options (``listen``: ``--zenoh-listen`` too, the relay's)."""
    g = p.add_argument_group("Zenoh")
    g.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT",
                   help="a Zenoh router to connect to, e.g. tcp/relay.example.com:7447 or "
                   "tls/relay.example.com:7447 (may be given several times)")
    if listen:
        g.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT",
                       help="be a Zenoh router listening here, e.g. tcp/0.0.0.0:7447 (may be "
                       "given several times)")
    g.add_argument("--zenoh-tls-ca", default=None, metavar="FILE",
                   help="CA certificate that signs the routers' certificates (tls/ endpoints)")
    g.add_argument("--zenoh-tls-cert", default=None, metavar="FILE",
                   help="this side's TLS certificate (a router's for tls/ listen endpoints)")
    g.add_argument("--zenoh-tls-key", default=None, metavar="FILE",
                   help="the private key of --zenoh-tls-cert")
    g.add_argument("--zenoh-lease", type=float, default=3.0, metavar="SECONDS",
                   help="a Zenoh link silent this long counts as dead (default 3): a robot "
                   "gone is told to its clients within it")
    g.add_argument("--zenoh-insecure", action="store_true",
                   help="allow Zenoh links beyond this machine without TLS (a robot) or "
                   "without mutual TLS (a relay listening): anyone who reaches them can pose "
                   "as a robot or drive one; refused without this, and warned with it")
    if listen:
        g.add_argument("--zenoh-mtls", action="store_true",
                       help="ask whoever connects for a certificate signed by --zenoh-tls-ca "
                       "(mutual TLS: a robot's certificate's common name is its robot name); "
                       "needs --zenoh-robot or --zenoh-relay, which say who may come in")
        g.add_argument("--zenoh-robot", action="append", default=[], metavar="NAME",
                       help="with --zenoh-mtls: a robot let in by its certificate, on the keys "
                       "under its own name only (may be given several times)")
        g.add_argument("--zenoh-relay", action="append", default=[], metavar="NAME",
                       help="with --zenoh-mtls: another relay let in by its certificate's "
                       "common name, on every robot's keys (those naming a relay: under its "
                       "own name only; may be given several times)")


def options_from_args(args: argparse.Namespace) -> ZenohOptions:
    """The options :func:`add_arguments` added, as :class:`ZenohOptions`."""
    return ZenohOptions(connect=list(args.zenoh_connect),
                        listen=list(getattr(args, "zenoh_listen", []) or []),
                        tls_ca=args.zenoh_tls_ca, tls_cert=args.zenoh_tls_cert,
                        tls_key=args.zenoh_tls_key, mtls=getattr(args, "zenoh_mtls", False),
                        robots=list(getattr(args, "zenoh_robot", []) or []),
                        relays=list(getattr(args, "zenoh_relay", []) or []),
                        lease=args.zenoh_lease, insecure=args.zenoh_insecure)
