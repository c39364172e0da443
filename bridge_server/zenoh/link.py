"""Opening the Zenoh session of a robot's exporter or of a relay, from command-line options.

``zenoh`` is imported when a session is opened, not with this module, so the bridge's
command line parses where it is not installed.

The robot and a relay that uses routers are Zenoh clients (``--zenoh-connect``: they dial
out, nothing dials in); a relay with ``--zenoh-listen`` is itself a router in-process.
Multicast scouting is off: who talks to whom is what the options say, nothing found on
the LAN. A client waits for its router as long as it takes (the session opens in a thread,
so the event loop goes on), and Zenoh reconnects it by itself if the link drops.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..interfaces import BridgeError

if TYPE_CHECKING:
    import zenoh

__all__ = ["ZenohOptions", "add_arguments", "open_session", "options_from_args"]


@dataclass
class ZenohOptions:
    """Where the session connects or listens, and its TLS files."""

    connect: list[str] = field(default_factory=list)
    listen: list[str] = field(default_factory=list)
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    @property
    def mode(self) -> str:
        """``router`` when it listens, else ``client``."""
        return "router" if self.listen else "client"

    def config(self) -> zenoh.Config:
        """The Zenoh configuration; ``BridgeError`` naming an option that does not fit."""
        import zenoh

        if not self.connect and not self.listen:
            raise BridgeError("no Zenoh endpoint: give --zenoh-connect or --zenoh-listen")
        for what, path in (("--zenoh-tls-ca", self.tls_ca), ("--zenoh-tls-cert", self.tls_cert),
                           ("--zenoh-tls-key", self.tls_key)):
            if path is not None and not os.access(path, os.R_OK):
                raise BridgeError(f"{what} {path}: not a readable file")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise BridgeError("--zenoh-tls-cert and --zenoh-tls-key go together")
        uses_tls = any(e.startswith(("tls/", "quic/")) for e in [*self.connect, *self.listen])
        if uses_tls and self.listen and self.tls_cert is None:
            raise BridgeError("a tls/ or quic/ --zenoh-listen endpoint needs --zenoh-tls-cert "
                              "and --zenoh-tls-key")
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(self.mode))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("scouting/gossip/enabled", "false" if not self.listen else "true")
        conf.insert_json5("connect/endpoints", json.dumps(self.connect))
        conf.insert_json5("listen/endpoints", json.dumps(self.listen))
        # Robots and relays meet over networks: Zenoh's shared memory between processes of
        # one machine (its default for payloads over ~3 KB) would bypass the link and its
        # TLS, so the link carries everything here too.
        conf.insert_json5("transport/shared_memory/enabled", "false")
        # a client waits for its routers (in open_session's thread) instead of failing
        conf.insert_json5("connect/timeout_ms", json.dumps({"client": -1, "router": 0}))
        tls = "transport/link/tls"
        if self.tls_ca is not None:
            conf.insert_json5(f"{tls}/root_ca_certificate", json.dumps(self.tls_ca))
        if self.tls_cert is not None and self.tls_key is not None:
            side = "listen" if self.listen else "connect"
            conf.insert_json5(f"{tls}/{side}_certificate", json.dumps(self.tls_cert))
            conf.insert_json5(f"{tls}/{side}_private_key", json.dumps(self.tls_key))
        return conf


async def open_session(options: ZenohOptions) -> zenoh.Session:
    """Open the session in a thread of its own (a client waits there until a router
    answers); cancelled meanwhile, the session is closed as soon as it opens. The thread is a
    daemon: a process told to stop while no router answered exits without waiting for it."""
    import zenoh

    conf = options.config()
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


def options_from_args(args: argparse.Namespace) -> ZenohOptions:
    """The options :func:`add_arguments` added, as :class:`ZenohOptions`."""
    return ZenohOptions(connect=list(args.zenoh_connect),
                        listen=list(getattr(args, "zenoh_listen", []) or []),
                        tls_ca=args.zenoh_tls_ca, tls_cert=args.zenoh_tls_cert,
                        tls_key=args.zenoh_tls_key)
