"""A bare Zenoh router for the fleet benchmark (``python -m bench.zrouter --listen EP``).

It is the router a relay with ``--zenoh-listen`` runs in-process (the same configuration,
:meth:`~bridge_server.zenoh.link.ZenohOptions.config`), without the relay: robots and relays
dial it, and ``--connect`` meshes it with another router. It prints ``zenoh router ready``
once its session is open and runs until SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys

from bridge_server.zenoh.link import ZenohOptions, open_session

__all__ = ["main"]


async def _run(args: argparse.Namespace) -> int:
    session = await open_session(ZenohOptions(listen=list(args.listen),
                                              connect=list(args.connect or [])))
    print(f"zenoh router ready {session.zid()}", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    session.close()  # type: ignore[no-untyped-call]
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the router until told to stop."""
    p = argparse.ArgumentParser(prog="python -m bench.zrouter", description=__doc__)
    p.add_argument("--listen", action="append", required=True, metavar="ENDPOINT",
                   help="where robots and relays dial it (repeatable)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="another router to mesh with (repeatable)")
    return asyncio.run(_run(p.parse_args(argv)))


if __name__ == "__main__":
    sys.exit(main())
