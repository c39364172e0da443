"""The robot knows its uplink: whether a router holds its presence now, and what it sends.

Zenoh tells a robot's session when a router's transport opens and closes, but a transport
whose peer fell silent (a cut cable, a dead Wi-Fi cell) may be closed only when the link
comes back, so a robot relying on that alone learns of its outage at its end. The robot
therefore asks its routers itself: every :data:`PROBE_PERIOD`, while it serves, it asks the
network for the presence tokens of its name (:func:`router_answers`), which only a router
that holds them answers. The uplink is

- **up** while a router answered within the last :data:`DOWN_AFTER` seconds (less than the
  lease: the relays' clients are told the robot went away after the lease, and its own log
  says so first), and **down** from the first probe that finds it silent that long, or at
  once when its last router's transport closes;
- **admitted** once a router answered for the robot's own token: the relay lets the robot
  use the keys under its name. A robot whose session opened but is not admitted within
  :data:`ADMIT_WAIT` logs an ERROR with the reason it can see (its certificate's common name
  against ``--robot``) and the flag or certificate to fix; it says it "is on Zenoh" only
  once admitted.

:class:`Uplink` keeps that state, the messages and bytes the robot put for its relays (rates
over :data:`RATE_WINDOW`), and gives the robot's ``status.json`` section
(:meth:`Uplink.status`), its ``/metrics`` families (:meth:`Uplink.metrics`) and its
readiness with ``--no-websocket`` (:meth:`Uplink.not_ready`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from bridge_server.zenoh import keys
from bridge_server.zenoh.link import ZenohOptions

if TYPE_CHECKING:
    import zenoh
    from prometheus_client.core import Metric

__all__ = ["ADMIT_WAIT", "CHECK_TICK", "DOWN_AFTER", "PROBE_PERIOD", "RATE_WINDOW", "Uplink",
           "certificate_name", "router_answers", "uplink_use"]

log = logging.getLogger("bridge_server.zenoh.exporter")  # the robot's one log for its link

PROBE_PERIOD = 1.0
"""Seconds between two probes of the robot's routers (each a liveliness query of a few
bytes, answered by the router from its own tables: one a second per robot)."""

CHECK_TICK = 0.25
"""Seconds between two looks at a probe still waiting for its answer."""

DOWN_AFTER = 2.0
"""Seconds without a router's answer after which the uplink counts as down (within the 3 s
lease of a Zenoh link, so the robot says it first)."""

ADMIT_WAIT = 2.0
"""Seconds a robot's open session waits for a router to hold its presence before it says,
as an ERROR, that the relay does not admit it (and why, as far as it can see)."""

RATE_WINDOW = 5.0
"""Seconds over which the messages and bytes sent per second are averaged."""


async def router_answers(session: zenoh.Session, key: str, own: str, timeout: float) -> bool:
    """Whether a router answers a liveliness query of ``key`` within ``timeout`` s: a token
    of another session, or ``own`` (this session's token, which the session also answers
    itself) a second time."""

    loop = asyncio.get_running_loop()
    done: asyncio.Future[bool] = loop.create_future()
    seen: list[str] = []

    def settle(answered: bool) -> None:
        if not done.done():
            done.set_result(answered)

    def reply(r: zenoh.Reply) -> None:
        if r.ok is None:
            return
        seen.append(str(r.ok.key_expr))
        if seen[-1] != own or seen.count(own) > 1:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(settle, True)

    def end() -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(settle, False)

    from bridge_server.zenoh.inbox import direct

    session.liveliness().get(key, direct(reply, end), timeout=timeout)
    return await done


def certificate_name(path: str | None) -> str | None:
    """The common name of the PEM certificate at ``path`` (``None``: no certificate, or none
    readable there: Zenoh's own check says why)."""
    if path is None:
        return None
    try:
        from cryptography import x509
        from cryptography.x509.oid import NameOID

        with open(path, "rb") as f:
            cert = x509.load_pem_x509_certificate(f.read())
        names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
        return str(names[0].value) if names else None
    except (OSError, ValueError, ImportError):
        return None


class _Robot(Protocol):
    """What :func:`uplink_use` reads of the robot's exporter."""

    policy_refused: dict[tuple[str, str], int]
    name_refusals: int
    uplink: Uplink

    @property
    def putter(self) -> Any:
        """Its :class:`~.putter.Putter`."""

    @property
    def replay_budget(self) -> Any:
        """Its :class:`~.replay.ReplayBudget`."""

    def replay_windows(self) -> dict[str, tuple[int, int]]:
        """Its replay windows' messages and bytes, by topic."""


def uplink_use(robot: _Robot) -> tuple[dict[str, int], dict[str, int], dict[str, int]]:
    """The replay windows' use of ``robot``, its refusals by kind and what waits for its
    putting thread (:mod:`.putter`), for its uplink's status and metrics."""
    windows = robot.replay_windows().values()
    budget = robot.replay_budget
    return ({"topics": len(windows), "messages": sum(n for n, _ in windows),
             "bytes": sum(b for _, b in windows), "reserved": budget.reserved,
             "total": budget.total},
            {"policy": sum(robot.policy_refused.values()), "name": robot.name_refusals,
             "admission": int(robot.uplink.refusal is not None)},
            {"waiting_bytes": robot.putter.waiting, "dropped": robot.putter.dropped})


class Uplink:
    """Robot ``robot``'s view of its uplink (see the module's text)."""

    def __init__(self, robot: str, options: ZenohOptions,
                 clock: Callable[[], float] = time.time) -> None:
        self.robot = robot
        self.options = options
        self.clock = clock
        self.routers: set[str] = set()
        """The Zenoh ids of the routers with a transport to the robot now."""
        self.up = False
        self.since: float | None = None
        """Wall-clock time the uplink last came up or went down (``None``: never up)."""
        self.lost = 0
        """How many times the uplink went down."""
        self.admitted = False
        """Whether a router held the robot's presence since its session opened."""
        self.refusal: str | None = None
        """Why the relay does not admit the robot, once it waited :data:`ADMIT_WAIT`."""
        self.messages = 0
        """Messages the robot put for its relays."""
        self.bytes = 0
        """Payload bytes of those."""
        self._heard = 0.0  # loop time of the last router's answer
        self._serving_at: float | None = None  # loop time the robot started serving
        self._samples: deque[tuple[float, int, int]] = deque()
        self._task: asyncio.Task[None] | None = None

    # -- what the exporter tells it ----------------------------------------------------------

    def sent(self, size: int) -> None:
        """The robot put one message of ``size`` payload bytes for its relays."""
        self.messages += 1
        self.bytes += size

    def transport(self, zid: str, opened: bool) -> None:
        """A router's transport opened or closed (Zenoh's transport events)."""
        if opened:
            self.routers.add(zid)
            self._came(f"router {zid}")
            return
        self.routers.discard(zid)
        if not self.routers:
            self._went(f"router {zid} closed or silent for the lease")

    def serving(self) -> None:
        """The robot declared its presence: said to be on Zenoh once a router holds it."""
        self._serving_at = asyncio.get_running_loop().time()
        self.admitted = False

    def watch(self, session: zenoh.Session, zid: str) -> None:
        """Probe the routers of ``session`` (this robot's, Zenoh id ``zid``) until closed."""
        self._task = asyncio.get_running_loop().create_task(self._probe(session, zid),
                                                            name="zenoh-uplink")

    async def close(self) -> None:
        """Stop probing."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    # -- the probe ---------------------------------------------------------------------------

    async def _probe(self, session: zenoh.Session, zid: str) -> None:
        import zenoh

        loop = asyncio.get_running_loop()
        own = keys.alive_key(self.robot, zid)  # declared while the robot serves
        pattern = f"{self.robot}/{keys.ALIVE}/*"
        while True:
            started = loop.time()
            # A probe waits for its answer as long as the uplink may be silent: an answer
            # late on a loaded machine still counts. Meanwhile it is looked at each tick.
            probe = asyncio.ensure_future(router_answers(session, pattern, own, DOWN_AFTER))
            try:
                while not (await asyncio.wait({probe}, timeout=CHECK_TICK))[0]:
                    self._check(loop.time())
                answered = probe.result()
            except zenoh.ZError:  # the session is closing
                return
            finally:
                probe.cancel()
            now = loop.time()
            self._sample(now)
            if answered:
                self._heard = now
                self._came("its router answered")
                if not self.admitted and self._serving_at is not None:
                    self.admitted, self.refusal = True, None
                    log.info("robot %s is on Zenoh (session %s): its router holds its presence",
                             self.robot, zid)
            self._check(now)
            await asyncio.sleep(max(0.0, PROBE_PERIOD - (loop.time() - started)))

    def _check(self, now: float) -> None:
        """The uplink down after :data:`DOWN_AFTER` s without an answer; a robot serving for
        :data:`ADMIT_WAIT` s that no router answered is not admitted (said once)."""
        if self.admitted and self.up and now - self._heard >= DOWN_AFTER:
            self._went(f"no router answered for {now - self._heard:.1f} s")
        elif (not self.admitted and self.refusal is None and self._serving_at is not None
              and self.routers and now - self._serving_at >= ADMIT_WAIT):
            self.refusal = self.not_admitted_reason()
            log.error("robot %s is not admitted by the relay: %s", self.robot, self.refusal)

    def _came(self, how: str) -> None:
        if self.up:
            return
        self.up, self.since = True, self.clock()
        self._heard = asyncio.get_running_loop().time()
        if self.lost:
            log.info("robot %s: its uplink to the Zenoh network is back (%s)", self.robot, how)

    def _went(self, why: str) -> None:
        if not self.up:
            return
        self.up, self.since = False, self.clock()
        self.lost += 1
        log.warning("robot %s: its uplink to the Zenoh network is gone (%s): ROS is served "
                    "meanwhile, relays' clients are told it went away, and it dials again",
                    self.robot, why)

    def not_admitted_reason(self) -> str:
        """Why a router may not hold this robot's presence, with what to fix."""
        opts = self.options
        name = certificate_name(opts.tls_cert)
        if opts.tls_cert is not None and name != self.robot:
            return (f"its certificate (--zenoh-tls-cert {opts.tls_cert}) is for "
                    f"{name or 'no common name'!r}, and a relay's router lets a robot use only "
                    f"the keys under its certificate's common name: give robot {self.robot}'s "
                    f"certificate ('roslibpy-lite-relay certs robot {self.robot}' makes one), or "
                    f"run this robot as --robot {name}")
        return (f"its router holds none of its tokens: the relay must name it with "
                f"--zenoh-robot {self.robot} (with --zenoh-mtls a relay lets in only the robots "
                "it names), or its access rules refuse the keys under "
                f"{self.robot}/; the relay's log says which")

    def dialing(self, waited: float) -> None:
        """No router has answered for ``waited`` s: say so, and what to check."""
        opts = self.options
        tls = any(e.startswith(("tls/", "quic/")) for e in opts.connect)
        where = ", ".join(opts.connect)
        if tls and opts.tls_cert is None:
            log.error("robot %s: no Zenoh router has let this robot in at %s for %.0f s: it "
                      "gives no certificate, and a relay with --zenoh-mtls refuses a robot "
                      "without one; give --zenoh-tls-cert and --zenoh-tls-key (robot %s's "
                      "certificate, 'roslibpy-lite-relay certs' makes one)", self.robot, where,
                      waited, self.robot)
            return
        log.warning(
            "robot %s: no Zenoh router has answered at %s for %.0f s (ROS is served "
            "meanwhile); %s; a router may also be full (Zenoh's transport/unicast/"
            "max_sessions, 1,000 unless set: its refusal is Zenoh's 'close message (reason "
            "INVALID)' in this log)", self.robot, where, waited,
            "if the router is up, it may refuse this robot's certificate: its log says why; "
            "with --zenoh-mtls the robot's certificate must be signed by the router's CA, "
            "allow client authentication (extendedKeyUsage=clientAuth) and have "
            f"{self.robot} as its common name ('roslibpy-lite-relay certs' makes one)"
            if tls else "check that the router is up and reachable there")

    # -- what it shows -----------------------------------------------------------------------

    def _sample(self, now: float) -> None:
        samples = self._samples
        samples.append((now, self.messages, self.bytes))
        while len(samples) > 2 and now - samples[1][0] >= RATE_WINDOW:
            samples.popleft()

    def rates(self) -> tuple[float, float]:
        """Messages and bytes sent per second over the last :data:`RATE_WINDOW` s."""
        if len(self._samples) < 2:
            return 0.0, 0.0
        (t0, m0, b0), (t1, m1, b1) = self._samples[0], self._samples[-1]
        span = max(t1 - t0, 1e-9)
        return (m1 - m0) / span, (b1 - b0) / span

    def not_ready(self) -> str | None:
        """Why a robot reached only through relays is not ready (``None``: its uplink is up
        and a router holds its presence)."""
        if not self.up:
            return f"uplink to Zenoh ({', '.join(self.options.connect)}) is down"
        if not self.admitted:
            return self.refusal or "not admitted by a relay yet"
        return None

    def status(self, replay: Mapping[str, Any], refusals: Mapping[str, int],
               putting: Mapping[str, int]) -> dict[str, Any]:
        """The robot's ``relay_uplink`` section of ``status.json`` (``replay``: its replay
        windows' use; ``refusals``: its counts of refused requests, by kind; ``putting``:
        the bytes waiting to be put and the messages dropped for want of room there)."""
        per_s, bytes_per_s = self.rates()
        return {
            "robot": self.robot, "routers": list(self.options.connect),
            "connected": sorted(self.routers), "up": self.up, "since": self.since,
            "lost": self.lost, "admitted": self.admitted, "refusal": self.refusal,
            "messages": self.messages, "bytes": self.bytes,
            "messages_per_s": round(per_s, 2), "bytes_per_s": round(bytes_per_s, 1),
            "rate_window_s": RATE_WINDOW, "replay": dict(replay), "refusals": dict(refusals),
            "putting": dict(putting)}

    def metrics(self, replay: Mapping[str, Any], refusals: Mapping[str, int],
                putting: Mapping[str, int]) -> list[Metric]:
        """The robot's ``/metrics`` families of its uplink (the same as :meth:`status`)."""
        from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

        labels = ["robot"]
        up = GaugeMetricFamily("roslibpy_bridge_relay_uplink_up", "1 while a Zenoh router "
                               "holds the robot's presence, else 0.", labels=labels)
        up.add_metric([self.robot], 1.0 if self.up and self.admitted else 0.0)
        since = GaugeMetricFamily("roslibpy_bridge_relay_uplink_since_seconds", "Unix time "
                                  "the uplink last came up or went down.", labels=labels)
        if self.since is not None:
            since.add_metric([self.robot], self.since)
        lost = CounterMetricFamily("roslibpy_bridge_relay_uplink_lost", "Times the robot's "
                                   "uplink went down.", labels=labels)
        lost.add_metric([self.robot], self.lost)
        sent = CounterMetricFamily("roslibpy_bridge_relay_sent_messages", "Messages the robot "
                                   "put for its relays.", labels=labels)
        sent.add_metric([self.robot], self.messages)
        sent_bytes = CounterMetricFamily("roslibpy_bridge_relay_sent_bytes", "Payload bytes "
                                         "the robot put for its relays.", labels=labels)
        sent_bytes.add_metric([self.robot], self.bytes)
        window = GaugeMetricFamily("roslibpy_bridge_relay_replay_reserved_bytes", "Bytes the "
                                   "replay windows reserve, of --relay-replay-total-bytes.",
                                   labels=labels)
        window.add_metric([self.robot], float(replay.get("reserved", 0)))
        waiting = GaugeMetricFamily("roslibpy_bridge_relay_put_waiting_bytes", "Payload bytes "
                                    "waiting for the robot's putting thread.", labels=labels)
        waiting.add_metric([self.robot], float(putting.get("waiting_bytes", 0)))
        dropped = CounterMetricFamily("roslibpy_bridge_relay_put_dropped_messages", "Messages "
                                      "dropped before the robot's link: the bytes waiting "
                                      "for its putting thread were at their bound, or they "
                                      "waited too long.", labels=labels)
        dropped.add_metric([self.robot], putting.get("dropped", 0))
        refused = CounterMetricFamily("roslibpy_bridge_relay_refusals", "Requests of relays the "
                                      "robot refused, and refusals of the robot, by kind.",
                                      labels=["robot", "kind"])
        for kind, n in sorted(refusals.items()):
            refused.add_metric([self.robot, kind], n)
        return [up, since, lost, sent, sent_bytes, window, waiting, dropped, refused]
