"""The security options of the command line and the configuration they make."""

from __future__ import annotations

import argparse
import getpass
import os
from dataclasses import dataclass

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.constants import MAX_MESSAGE_SIZE
from rosbridge_core.security.credentials import is_loopback

__all__ = [
    "MAX_MESSAGE_SIZE",
    "SecurityConfig",
    "add_arguments",
    "check_readable",
    "config_from_args",
    "exposure_refusal",
    "parse_origins",
    "user_name",
]

"""The largest inbound frame in bytes by default (``--max-message-size``, of the bridge and
the relay): a larger one closes the connection (1009), and the pieces of a client's
incomplete ops are held to it all together."""


@dataclass
class SecurityConfig:
    """The security options of the command line (0 or None: no limit / off)."""

    certfile: str | None = None
    keyfile: str | None = None
    client_ca: str | None = None
    auth_file: str | None = None
    allowed_origins: list[str] | None = None
    max_clients: int = 1000
    max_clients_per_address: int = 0
    handshake_timeout: float = 10.0
    max_op_rate: float = 0.0
    op_burst: int = 0
    max_subscriptions: int = 1000
    max_publishers: int = 1000
    max_services: int = 1000
    max_goals: int = 1000
    max_subscription_ids: int = 100
    max_queue_length: int = 1000
    max_queued_messages: int = 10_000
    min_fragment_size: int = 1024
    inbound_budget: int = 32 * 1024 * 1024
    notsent_lowat: int = 64 * 1024
    inbound_budget_total: int = 256 * 1024 * 1024


def parse_origins(text: str | None) -> list[str] | None:
    """``--allowed-origins`` ("https://a.example,https://b.example") as a list."""
    if text is None:
        return None
    return [o.strip() for o in text.split(",") if o.strip()]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The security options of ``roslibpy-lite-bridge`` (see SECURITY.md)."""
    g = p.add_argument_group("security (see SECURITY.md)")
    d = SecurityConfig()
    g.add_argument("--certfile", help="PEM certificate chain: serve wss:// (TLS)")
    g.add_argument("--keyfile", help="PEM private key of --certfile (if not in it)")
    g.add_argument("--client-ca", help="PEM CA bundle: require client certificates (mutual TLS)")
    g.add_argument("--auth-file", help="TOML file of roles and principals: require a token "
                   "(make one with: roslibpy-lite-bridge add-principal NAME --role ROLE "
                   "--auth-file FILE)")
    g.add_argument("--insecure", action="store_true",
                   help="allow a non-loopback --host without --auth-file (anyone who reaches "
                   "the port may do anything; a warning is logged at every start)")
    g.add_argument("--allowed-origins", help="comma-separated browser origins allowed to "
                   "connect, e.g. https://ui.example.com (clients without Origin always may)")
    g.add_argument("--max-clients", type=int, default=d.max_clients,
                   help=f"most connected clients in all (default {d.max_clients}; 0: no limit)")
    g.add_argument("--max-clients-per-address", type=int, default=d.max_clients_per_address,
                   help="most clients from one IP address (default 0: no limit; behind a "
                   "proxy every client has the proxy's address)")
    g.add_argument("--handshake-timeout", type=float, default=d.handshake_timeout,
                   help="seconds to finish TLS, the websocket handshake and (with an auth file) "
                   f"authentication (default {d.handshake_timeout:g})")
    g.add_argument("--max-op-rate", type=float, default=d.max_op_rate,
                   help="ops per second per client; over it: a warning, ops dropped, then a "
                   "close with 1008 (default 0: no limit)")
    g.add_argument("--op-burst", type=int, default=d.op_burst,
                   help="ops a client may send at once above the rate (default: one second's)")
    g.add_argument("--max-subscriptions", type=int, default=d.max_subscriptions,
                   help=f"topics one client may subscribe to (default {d.max_subscriptions})")
    g.add_argument("--max-publishers", type=int, default=d.max_publishers,
                   help=f"topics one client may publish on (default {d.max_publishers})")
    g.add_argument("--max-services", type=int, default=d.max_services,
                   help=f"services one client may serve, and actions likewise "
                   f"(default {d.max_services})")
    g.add_argument("--max-goals", type=int, default=d.max_goals,
                   help=f"action goals one client may have in flight (default {d.max_goals})")
    g.add_argument("--max-subscription-ids", type=int, default=d.max_subscription_ids,
                   help="subscription ids one client may hold on one topic (they merge into one "
                   f"subscription; default {d.max_subscription_ids})")
    g.add_argument("--max-queue-length", type=int, default=d.max_queue_length,
                   help="largest queue_length a subscription may ask for; larger ones are "
                   f"lowered to it with a warning (default {d.max_queue_length})")
    g.add_argument("--max-queued-messages", type=int, default=d.max_queued_messages,
                   help="messages waiting to be sent to one client over all its subscriptions; "
                   "over it the oldest of the subscription are dropped "
                   f"(default {d.max_queued_messages})")
    g.add_argument("--min-fragment-size", type=int, default=d.min_fragment_size,
                   help="smallest fragment_size a subscription may ask for; smaller ones are "
                   f"raised to it with a warning (default {d.min_fragment_size} bytes)")
    g.add_argument("--notsent-lowat", type=int, default=d.notsent_lowat,
                   help="bytes the kernel may hold unsent per client (TCP_NOTSENT_LOWAT): "
                   "what a slow link cannot carry yet waits in the subscription queues, whose "
                   f"drop policy keeps data fresh (default {d.notsent_lowat >> 10} KiB; 0: the "
                   "kernel's default)")
    g.add_argument("--inbound-budget", type=int, default=d.inbound_budget,
                   help="bytes of received, not yet handled data per client before the bridge "
                   f"stops reading it (default {d.inbound_budget >> 20} MiB)")
    g.add_argument("--inbound-budget-total", type=int, default=d.inbound_budget_total,
                   help="the same for all clients together "
                   f"(default {d.inbound_budget_total >> 20} MiB)")


def config_from_args(args: argparse.Namespace) -> SecurityConfig:
    """The :class:`SecurityConfig` of parsed command-line arguments."""
    return SecurityConfig(
        certfile=args.certfile,
        keyfile=args.keyfile,
        client_ca=args.client_ca,
        auth_file=args.auth_file,
        allowed_origins=parse_origins(args.allowed_origins),
        max_clients=args.max_clients,
        max_clients_per_address=args.max_clients_per_address,
        handshake_timeout=args.handshake_timeout,
        max_op_rate=args.max_op_rate,
        op_burst=args.op_burst,
        max_subscriptions=args.max_subscriptions,
        max_publishers=args.max_publishers,
        max_services=args.max_services,
        max_goals=args.max_goals,
        max_subscription_ids=args.max_subscription_ids,
        max_queue_length=args.max_queue_length,
        max_queued_messages=args.max_queued_messages,
        min_fragment_size=args.min_fragment_size,
        inbound_budget=args.inbound_budget,
        notsent_lowat=args.notsent_lowat,
        inbound_budget_total=args.inbound_budget_total,
    )


def exposure_refusal(args: argparse.Namespace) -> str | None:
    """Why the bridge must not start with these options (``None``: it may).

    A bridge listening beyond this machine without ``--auth-file`` lets anyone who reaches
    the port drive the robot; it starts so only when ``--insecure`` says that is meant.
    """
    if is_loopback(args.host) or args.auth_file or args.insecure:
        return None
    return (f"--host {args.host or '(every address)'} is reachable from other machines: give "
            "--auth-file FILE (SECURITY.md), or --insecure to serve everyone who reaches the "
            "port, or --host 127.0.0.1")


def user_name() -> str:
    """The name of the user this process runs as (its uid if it has none)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return str(os.getuid())


def check_readable(config: SecurityConfig) -> None:
    """Raise :class:`BridgeError` naming the option, the file and the user for the first
    configured file (certificate, key, CA, auth file) this process cannot read."""
    for option, path in (("--certfile", config.certfile), ("--keyfile", config.keyfile),
                         ("--client-ca", config.client_ca), ("--auth-file", config.auth_file)):
        if not path:
            continue
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            raise BridgeError(f"{option}: cannot read {path} as user {user_name()}: "
                              f"{exc.strerror or exc}") from None
