"""The robot's name and link on the Zenoh network: it holds its name by a ``@claim`` token
(a second robot of the name is refused, and waits until the first leaves), and follows its
transports to the routers (its uplink lost and back; back from an outage, it looks whether
another robot took its name meanwhile)."""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import ExporterBase, log
from bridge_server.zenoh.link import tokens

__all__ = ["CLAIM_RECHECK", "CLAIM_WAIT", "RETURN_LEASES", "RETURN_POLL", "Presence"]

CLAIM_WAIT = 1.0
"""Seconds the robot waits for the tokens of its name when it announces itself (and at
most between one holding it leaving and trying again)."""

RETURN_POLL = 0.25
"""Seconds before the second look at the claims of its name by a robot back from an
outage (the first is at once); each later wait is twice the one before, and the last look
is at the end of :data:`RETURN_LEASES` leases after its link is back. The network tells it
of another robot's claim as a rule (:meth:`Presence._on_claim`), but not always at once: a
look at once may find none, and the claim's token may not come. With a lease of 3 s that
is looks at 0, 0.25, 0.75, 1.75, 3.75 and 6 s: six, where a look every 0.25 s for one lease
made twelve, 6,000 queries to a router restarted under 500 robots in 3 s; a look each
second for one lease (three) was tried and withdrawn: a robot back to a name another took
meanwhile saw none of that robot's claim in its three looks, in one CI run of ten, and kept
the name."""

RETURN_LEASES = 2.0
"""Leases after its link is back during which a robot back from an outage looks at its
name's claims, and takes another robot's claim that comes as one made while it was away."""

CLAIM_RECHECK = 5.0
"""Seconds between two looks, by a robot refused its name, at whether the holder left (it
is told at once as a rule)."""


class Presence(ExporterBase):
    """The exporter's part that holds the robot's name and follows its uplink."""

    uplink_lost: int
    """How many times the robot lost its last router."""
    holding: bool
    """Whether this robot holds its name on Zenoh (and serves there)."""
    refused_by: set[str]
    """The Zenoh ids of the robots holding this robot's name while it waits for it."""
    name_refusals: int
    """Robots refused this robot's name while it held it."""
    _claim_changed: asyncio.Event
    _away_until: float
    """Loop time until which another robot's claim that comes is one made while this
    robot was away (its last uplink lost since it took its name: ``inf`` until the
    uplink is back, then :data:`RETURN_LEASES` leases more, the time the network takes to
    tell it the claims it missed)."""
    _returned: asyncio.Event
    """Set when the robot, back from an outage, may have met another robot's claim."""

    async def _claim(self, session: zenoh.Session, token: Any = None) -> Any:
        """Announce the robot's name (its ``@claim`` token; ``token``: one declared already)
        and hold it: the token of another robot there already means that robot holds the
        name, and this one withdraws its token, says why (an error, with both Zenoh ids)
        and, serving nothing on Zenoh, waits for that robot to leave (a robot restarted
        before its old session's lease ended waits for that lease). The token held,
        returned."""
        live = session.liveliness()
        told: set[str] = set()
        while True:
            self._claim_changed.clear()
            if token is None:
                token = live.declare_token(keys.claim_key(self.robot, self.zid))
            found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
            others = {keys.parse_alive(key)[1] for key in found} - {self.zid}
            if not others:
                if told:
                    log.info("robot %s: the robot that held its name left; this robot "
                             "(Zenoh id %s) takes it", self.robot, self.zid)
                self.refused_by = set()
                return token
            token.undeclare()
            token = None
            self.refused_by = others
            if others - told:
                told |= others
                log.error("robot %s: another robot holds this name on the Zenoh network "
                          "(Zenoh id %s): this robot (Zenoh id %s) is refused and serves "
                          "nothing on Zenoh until that one leaves (ROS is served meanwhile); "
                          "stop the other robot, or give this one another --robot name",
                          self.robot, ", ".join(sorted(others)), self.zid)
            await self._until_unclaimed(session)
            # Two robots that announced the name at once each withdrew for the other: they
            # try again at different times.
            await asyncio.sleep(random.uniform(0, CLAIM_WAIT))

    async def _until_unclaimed(self, session: zenoh.Session) -> None:
        """Wait until no other robot's claim of the name is on the network: told by a
        claim going (:meth:`_on_claim`), and asked again each ``CLAIM_RECHECK`` s besides
        (Zenoh may not tell a waiting robot of a token that goes: seen once in some runs,
        the waiting robot then waited for ever)."""
        while True:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(CLAIM_RECHECK):
                    await self._claim_changed.wait()
            self._claim_changed.clear()
            found = await tokens(session, f"{self.robot}/{keys.CLAIM}/*", CLAIM_WAIT)
            if not {keys.parse_alive(key)[1] for key in found} - {self.zid}:
                return

    def _on_claim(self, sample: zenoh.Sample) -> None:
        """Another session's token of the robot's name came or went: one gone may free the
        name for a robot waiting for it; one come while this robot holds the name is a robot
        refused (it withdraws when it sees this one's), said here too."""
        zid = keys.parse_alive(str(sample.key_expr))[1]
        if zid == self.zid:
            return
        if sample.kind != zenoh.SampleKind.PUT:
            self._claim_changed.set()
        elif self.holding and self._loop.time() < self._away_until:
            self._returned.set()  # back from an outage: another took the name meanwhile?
        elif self.holding:
            self.name_refusals += 1
            log.warning("robot %s: another robot (Zenoh id %s) announced this robot's name, "
                        "which this robot (Zenoh id %s) holds: it is refused, this one goes on "
                        "serving", self.robot, zid, self.zid)

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        """The robot's own log says when its uplink goes and comes back (its last router
        gone, or the first back): the relays' clients are told by their relays. Back, a
        robot that held its name looks whether another took it meanwhile (:meth:`_hold`)."""
        zid = str(event.transport.zid)
        if event.kind == zenoh.SampleKind.PUT:
            first = not self.uplinks
            self.uplinks.add(zid)
            if first:
                self._uplink_since = self._loop.time()
            self.uplink.transport(zid, opened=True)
            if first and self._away_until == math.inf:
                self._away_until = self._loop.time() + RETURN_LEASES * self.options.lease
                self._returned.set()
        elif zid in self.uplinks:
            self.uplinks.discard(zid)
            if not self.uplinks:
                self.uplink_lost += 1
                if self.holding:
                    self._away_until = math.inf
            self.uplink.transport(zid, opened=False)
