"""How workers see each other: each serves its snapshot on a unix socket, and reads the others'.

With ``--workers N`` every worker's status page and ``/metrics`` show the whole bridge: the
web routes (:mod:`bridge_server.http.web`) merge this worker's snapshot with the ones fetched
here. The supervisor itself is :mod:`bridge_server.workers.supervisor`.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, Protocol

__all__ = ["PEER_TIMEOUT", "serve_peer_socket"]

PEER_TIMEOUT = 1.0
"""Seconds to wait for another worker's snapshot."""


def _sock_path(directory: str, index: int) -> str:
    return os.path.join(directory, f"worker-{index}.sock")


class Snapshots(Protocol):
    """A worker's status routes (:class:`~bridge_server.http.web.Web`): its own snapshot,
    and where the other workers' are fetched from."""

    peers: Callable[[], Awaitable[list[dict[str, Any]]]] | None

    def local(self) -> dict[str, Any]:
        """This process's snapshot."""
        ...


async def serve_peer_socket(web: Snapshots, directory: str, index: int) -> asyncio.Server:
    """Answer other workers' requests for this worker's snapshot; set ``web.peers``."""
    path = _sock_path(directory, index)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)  # left by a worker of this index that died

    async def handle(_reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            writer.write(json.dumps(web.local(), separators=(",", ":")).encode())
            await writer.drain()
        except OSError:
            pass
        finally:
            writer.close()

    server = await asyncio.start_unix_server(handle, path)

    async def peers() -> list[dict[str, Any]]:
        others = [
            str(p) for p in Path(directory).glob("worker-*.sock") if str(p) != path
        ]
        got = await asyncio.gather(*(_fetch(p) for p in others))
        return [g for g in got if g is not None]

    web.peers = peers
    return server


async def _fetch(path: str) -> dict[str, Any] | None:
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_unix_connection(path), PEER_TIMEOUT)
        try:
            data = await asyncio.wait_for(reader.read(), PEER_TIMEOUT)
        finally:
            writer.close()
        snap: dict[str, Any] = json.loads(data)
        return snap
    except (OSError, TimeoutError, ValueError):
        return None  # a worker that is restarting: left out of this view
