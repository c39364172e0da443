"""Helpers for the load and fault tests: a client that never reads, graph polling, QoS profiles."""

from __future__ import annotations

import base64
import contextlib
import json
import os
import socket
import struct
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from tests.helpers import async_wait_until


def qos(*, depth: int = 10, best_effort: bool = False, latched: bool = False) -> QoSProfile:
    """A KEEP_LAST profile with the given depth, reliability and durability."""
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class StalledClient:
    """A raw TCP websocket client that completes the handshake, sends ops, and never reads.

    Its receive buffer is tiny, so the bridge's side of the socket fills at once.
    """

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(10)
        self.sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        reply = b""
        while b"\r\n\r\n" not in reply:  # read the handshake reply byte by byte, nothing more
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError("the bridge closed the connection during the handshake")
            reply += chunk
        status = reply.split(b"\r\n", 1)[0]
        if b" 101 " not in status:
            raise ConnectionError(f"handshake refused: {status!r}")

    def send(self, op: dict[str, Any]) -> None:
        """Send one op as a masked text frame."""
        self._send_frame(0x1, json.dumps(op).encode())

    def _send_frame(self, opcode: int, payload: bytes) -> None:
        mask = os.urandom(4)
        n = len(payload)
        if n < 126:
            head = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
        elif n < 65536:
            head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def read_op(self) -> Any:
        """Read the next whole (unfragmented, unmasked) text frame and decode it as JSON;
        a ping on the way (the bridge's keepalive, once the client was silent) is answered
        with its pong, as any websocket library does."""
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack("!H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack("!Q", self._read(8))[0]
            payload = self._read(n)
            opcode = b0 & 0x0F
            if opcode == 0x9:  # ping
                self._send_frame(0xA, payload)
                continue
            if opcode == 0xA:  # pong
                continue
            assert opcode == 0x1, f"expected a text frame, got opcode {opcode}"
            return json.loads(payload)

    def sync(self, id: str = "stall-sync") -> list[Any]:
        """Make sure everything sent so far was handled: send a cheap call and read until its reply.

        Use it before any data can flow to this client; afterwards it never reads again.
        Returns the other ops that arrived before the reply (e.g. error statuses).
        """
        self.send({"op": "call_service", "service": "/rosapi/get_ros_version", "id": id})
        before: list[Any] = []
        while True:
            op = self.read_op()
            if op.get("op") == "service_response" and op.get("id") == id:
                return before
            before.append(op)

    def _read(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("the bridge closed the connection")
            buf += chunk
        return buf

    def close(self) -> None:
        """Drop the connection (no closing handshake)."""
        with contextlib.suppress(OSError):
            self.sock.close()


def service_in_graph(node: Any, name: str) -> bool:
    """Whether the ROS graph lists a service called ``name``."""
    return any(n == name for n, _ in node.get_service_names_and_types())


async def wait_count(fn: Any, topic: str, want: int, timeout: float = 10.0) -> None:
    """Poll ``fn(topic)`` (``count_publishers``/``count_subscribers``) until it equals ``want``."""
    await async_wait_until(lambda: fn(topic) == want, timeout, f"{fn.__name__}({topic}) == {want}")
