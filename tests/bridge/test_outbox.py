"""The outbox's writer over a real websocket connection: an idle writer's first message is
written before ``push`` returns, what follows in the same turn goes in one write after it."""

from __future__ import annotations

import asyncio
from typing import Any

from websockets.asyncio.client import connect
from websockets.asyncio.server import ServerConnection, serve

from bridge_server.outbox import Outbox, Subscription
from tests.helpers import async_wait_until


class _Text:
    """Stands for an Incoming: the outbox only asks it for its JSON text."""

    def __init__(self, text: str) -> None:
        self.text = text

    def json_text(self, _name: str | None = None) -> str:
        return self.text


async def test_an_idle_writer_writes_at_once_and_batches_what_follows() -> None:
    conns: asyncio.Queue[ServerConnection] = asyncio.Queue()

    async def handler(ws: ServerConnection) -> None:
        await conns.put(ws)
        await ws.wait_closed()

    async with serve(handler, "127.0.0.1", 0) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        async with connect(f"ws://127.0.0.1:{port}") as client:
            ws = await conns.get()
            box = Outbox(ws, 1, 100, 0, 5.0, warn=lambda _msg: None)
            writer = asyncio.create_task(box.writer())
            await async_wait_until(lambda: box.idle, 5.0, "the writer idle")
            writes: list[bytes] = []
            transport: Any = ws.transport
            real_write = transport.write

            def counting_write(data: bytes) -> None:
                writes.append(data)
                real_write(data)

            transport.write = counting_write
            sub = Subscription(box, "/t", "/t")
            box.push(sub, _Text("first"))  # type: ignore[arg-type]
            assert len(writes) == 1, "an idle writer's first message waits for no turn"
            box.push(sub, _Text("second"))  # type: ignore[arg-type]
            box.send_text("a reply")
            box.push(sub, _Text("third"))  # type: ignore[arg-type]
            assert len(writes) == 1, "what follows in the same turn waits for the writer"
            got = [await asyncio.wait_for(client.recv(), 5.0) for _ in range(4)]
            assert got == ["first", "a reply", "second", "third"]  # replies go first
            assert len(writes) == 2, "the writer wrote the three that followed at once"
            await async_wait_until(lambda: box.idle, 5.0, "the writer idle again")
            box.close()
            box.push(sub, _Text("after close"))  # type: ignore[arg-type]
            assert len(writes) == 2, "a closed outbox writes nothing"
            await asyncio.wait_for(writer, 5.0)
