"""The inbound byte budget's accounting: what every connection counts in all goes back to zero.

A leak in the shared total would, over a long-running bridge, pause every
connection after each frame (the total stays over its budget for good); these
check that reading, closing with frames still queued and a cancelled read of a
fragmented message all give their bytes back.
"""

from __future__ import annotations

import asyncio

from websockets.frames import Frame, Opcode

from bridge_server.front.websocket import BudgetAssembler, Inbound

FRAME = 700


def _assembler(totals: Inbound, calls: list[str]) -> BudgetAssembler:
    return BudgetAssembler(1000, 1500, totals, high=64, low=16,
                            pause=lambda: calls.append("pause"),
                            resume=lambda: calls.append("resume"))


async def test_total_returns_to_zero_after_reads_and_closes() -> None:
    """Frames read, frames dropped by a close, and frames read after a close: the total ends at 0."""
    totals, calls = Inbound(), list[str]()
    read, half, dropped = (_assembler(totals, calls) for _ in range(3))
    for asm in (read, half, dropped):
        for _ in range(5):
            asm.put(Frame(Opcode.TEXT, b"x" * FRAME))
    assert totals.bytes == 15 * FRAME
    for _ in range(5):
        await read.get()
    for _ in range(2):
        await half.get()
    half.close()  # the connection ended with three frames still queued
    dropped.close()
    assert totals.bytes == 0
    assert await half.get() == "x" * FRAME  # still readable after the end; not counted twice
    assert totals.bytes == 0
    assert calls.count("pause") == 3  # each went over its own budget of 1000 bytes


async def test_cancelled_read_of_a_fragmented_message_gives_its_bytes_back() -> None:
    """A read cancelled between fragments puts them back, counted once; the whole read empties it."""
    totals, calls = Inbound(), list[str]()
    asm = _assembler(totals, calls)
    asm.put(Frame(Opcode.TEXT, b"a" * FRAME, fin=False))
    reader = asyncio.ensure_future(asm.get())
    await asyncio.sleep(0)  # the read takes the first fragment and waits for the next
    assert totals.bytes == 0
    reader.cancel()
    await asyncio.gather(reader, return_exceptions=True)
    assert totals.bytes == FRAME and asm.queue.bytes == FRAME
    asm.put(Frame(Opcode.CONT, b"b" * FRAME))
    assert await asm.get() == "a" * FRAME + "b" * FRAME
    assert totals.bytes == 0 and asm.queue.bytes == 0
