"""A client that is gone before its handshake is read has the address "unknown", not a
traceback: under uvloop (the relay's and the bridge's loop where installed) a closed
socket's peer name raises, and the relay logged an ERROR with a traceback for each such
client (40 % of its samples in a reconnect storm, issue 49)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
from typing import Any

import pytest

from rosbridge_core.security.credentials import UNKNOWN_ADDRESS, client_address

uvloop = pytest.importorskip("uvloop")


class _Connection:
    """What websockets' connection does for ``remote_address``: ask the transport."""

    def __init__(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport

    @property
    def remote_address(self) -> Any:
        return self.transport.get_extra_info("peername")


def _address_of_a_client_gone(wait_closed: bool) -> str:
    async def main() -> str:
        seen: asyncio.Future[str] = asyncio.get_running_loop().create_future()

        async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            if wait_closed:  # the client's reset ends the stream
                with contextlib.suppress(ConnectionError):
                    await reader.read()
            seen.set_result(client_address(_Connection(writer.transport)))
            writer.close()

        server = await asyncio.start_server(handle, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        client = socket.create_connection(("127.0.0.1", port))
        if wait_closed:  # a reset, as a client killed mid-handshake sends
            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            client.close()
        try:
            return await asyncio.wait_for(seen, 10)
        finally:
            client.close()
            server.close()
            await server.wait_closed()

    result: str = uvloop.run(main())
    return result


def test_a_client_gone_before_its_handshake_has_the_unknown_address() -> None:
    """Under uvloop, the address of a client whose socket was reset is "unknown"."""
    assert _address_of_a_client_gone(wait_closed=True) == UNKNOWN_ADDRESS


def test_a_client_still_there_has_its_address() -> None:
    """A client still connected has its IP address."""
    assert _address_of_a_client_gone(wait_closed=False) == "127.0.0.1"
