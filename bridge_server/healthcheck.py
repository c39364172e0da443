"""``roslibpy-lite-bridge healthcheck``: is the bridge on this machine ready?

It asks the bridge's ``/readyz`` at the port and scheme the bridge was started with: given
the bridge's own options (``healthcheck --port 9443 --certfile server.pem``), or, with none,
read from the command line of the one bridge running on this machine (``/proc``), which is
what a container's ``HEALTHCHECK`` needs: ``docker run IMAGE --port 9443 ...`` changes the
bridge's options, and the check follows them.

Over ``wss://`` it trusts ``--cafile`` if given, else exactly the certificate the bridge
serves (its ``--certfile``): the check proves the port answers with the configured
certificate, without a hostname (it connects to loopback). With ``--metrics-port`` it asks
that plain-HTTP port instead (the way to check a bridge that requires client certificates).
Exit status 0: ready; 1: not ready, not reachable, or not found (one line on stderr says
why; Docker reserves status 2).
"""

from __future__ import annotations

import argparse
import os
import ssl
import sys
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

__all__ = ["HealthcheckError", "bridge_argv", "main", "probe", "readyz_url"]

_WILDCARD = {"": "127.0.0.1", "0.0.0.0": "127.0.0.1", "::": "::1"}
_SUBCOMMANDS = {"healthcheck", "add-principal", "remove-principal"}


class HealthcheckError(Exception):
    """The options do not say where the bridge is."""


def _bridge_options(argv: list[str]) -> list[str] | None:
    """The options of a bridge's command line, or ``None`` if it is not a bridge's main
    process (a worker, a helper command, something else)."""
    for i, word in enumerate(argv):
        if Path(word).name == "roslibpy-lite-bridge":
            rest = argv[i + 1:]
            break
        if word == "-m" and argv[i + 1:i + 2] == ["bridge_server"]:
            rest = argv[i + 2:]
            break
    else:
        return None
    if (rest[:1] and rest[0] in _SUBCOMMANDS) or "--worker-index" in rest:
        return None
    return rest


def bridge_argv(proc: Path = Path("/proc")) -> list[str]:
    """The options of the one bridge running on this machine, from its command line."""
    found: list[list[str]] = []
    for entry in proc.iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            raw = (entry / "cmdline").read_bytes()
        except OSError:  # gone, or not ours to read
            continue
        options = _bridge_options([w.decode(errors="replace") for w in raw.split(b"\0")[:-1]])
        if options is not None:
            found.append(options)
    if len(found) != 1:
        raise HealthcheckError(
            ("no running roslibpy-lite-bridge found" if not found else
             f"{len(found)} roslibpy-lite-bridge processes run here")
            + "; give the bridge's options: roslibpy-lite-bridge healthcheck --port PORT ...")
    return found[0]


def readyz_url(args: argparse.Namespace) -> str:
    """The ``/readyz`` address of a bridge started with ``args`` (its parsed options)."""
    port = args.metrics_port if args.metrics_port is not None else args.port
    if not port:
        raise HealthcheckError("the bridge was given port 0 (any free port): give the port "
                               "it listens on: roslibpy-lite-bridge healthcheck --port PORT")
    host = _WILDCARD.get(args.host, args.host)
    if ":" in host:
        host = f"[{host}]"
    scheme = "https" if args.certfile and args.metrics_port is None else "http"
    return f"{scheme}://{host}:{port}/readyz"


def _tls_context(cafile: str) -> ssl.SSLContext:
    ctx = ssl.create_default_context(cafile=cafile)
    ctx.check_hostname = False  # loopback: the certificate names the robot, not 127.0.0.1
    ctx.verify_flags |= ssl.VERIFY_X509_PARTIAL_CHAIN  # the served certificate is trusted itself
    return ctx


def probe(url: str, cafile: str | None, timeout: float) -> str | None:
    """Ask ``url``; ``None`` if it answered 200, else why not (one line)."""
    context = _tls_context(cafile) if url.startswith("https:") and cafile else None
    try:
        with urllib.request.urlopen(url, timeout=timeout, context=context) as reply:
            status = int(reply.status)
    except urllib.error.HTTPError as exc:
        status = exc.code
    except (OSError, ssl.SSLError) as exc:
        reason = getattr(exc, "reason", None) or exc
        return f"{url}: {reason}"
    return None if status == 200 else f"{url}: HTTP {status} (not ready)"


def main(argv: list[str], parse_args: Callable[[list[str]], argparse.Namespace]) -> int:
    """``roslibpy-lite-bridge healthcheck [--cafile CA] [--timeout S] [BRIDGE OPTIONS...]``;
    ``parse_args`` reads the bridge's options (the entry point's own, handed in)."""
    p = argparse.ArgumentParser(
        prog="roslibpy-lite-bridge healthcheck",
        description="Exit 0 if the bridge on this machine is ready (its /readyz), else 1. "
        "Give the bridge's own options, or none to read them from the running bridge.",
        allow_abbrev=False,
    )
    p.add_argument("--cafile", help="CA bundle to verify wss:// with (default: trust the "
                   "bridge's own --certfile)")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait (default 3)")
    ours, bridge_options = p.parse_known_args(argv)
    try:
        args = parse_args(bridge_options or bridge_argv())
        url = readyz_url(args)
    except HealthcheckError as exc:
        print(f"healthcheck: {exc}", file=sys.stderr)
        return 1
    problem = probe(url, ours.cafile or args.certfile, ours.timeout)
    if problem is not None:
        print(f"healthcheck: not ready: {problem}", file=sys.stderr)
        return 1
    return 0
