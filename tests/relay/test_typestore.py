"""A robot's graph documents and types as the relay reads them (bridge_server/zenoh/typestore.py):
read off the loop, at most one each GRAPH_INTERVAL s, redefinitions at most one each
REDEFINE_INTERVAL s, the newest waiting winning; a message of too many fields refused before
it is built (issue 53, findings 5 and 6)."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import pytest

from bridge_server.zenoh.inbox import Faults
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.typestore import (
    GRAPH_INTERVAL,
    REDEFINE_INTERVAL,
    GraphReader,
    RobotTypes,
    TypeLimits,
    TypeRefused,
)

pytestmark = pytest.mark.timeout(60)

TYPE = "costly_msgs/msg/Thing"


def _doc(field: str, node: str = "n") -> bytes:
    return Snapshot(node=node, definitions={TYPE: f"int32 {field}\n"}).encode()


def test_a_message_of_too_many_fields_is_refused_before_it_is_built(
        caplog: pytest.LogCaptureFixture) -> None:
    """A 1,001-field message is refused naming --max-fields-per-type (logged once), and
    nothing of it is built; one of 1,000 fields is built."""
    types = RobotTypes("wide", TypeLimits())
    wide = "".join(f"float64 f{i}\n" for i in range(1001))
    with pytest.raises(TypeRefused, match=r"--max-fields-per-type \(1000\)"):
        types.load(TYPE, "msg", {TYPE: wide})
    assert len(types.store) == 0
    assert [r for r in caplog.records if r.levelno == logging.WARNING
            and "--max-fields-per-type" in r.getMessage()]
    ok = "costly_msgs/msg/Fits"
    assert types.load(ok, "msg", {ok: "".join(f"float64 f{i}\n" for i in range(1000))})


async def test_redefinitions_are_read_at_most_once_each_interval_and_the_newest_wins(
        caplog: pytest.LogCaptureFixture) -> None:
    """A type redefined with each of 40 documents over 4 s: the relay reads a document at
    most each GRAPH_INTERVAL s and builds the types anew at most each REDEFINE_INTERVAL s;
    the last document is the one it ends with, its type built from it."""
    caplog.set_level(logging.WARNING)
    loop = asyncio.get_running_loop()
    types = RobotTypes("redefiner", TypeLimits())
    taken: list[Snapshot] = []
    reader = GraphReader(loop, types, Faults("redefiner"), taken.append)
    start = loop.time()
    for i in range(40):
        reader.offer(_doc(f"v{i}", node=f"n{i}"))
        await asyncio.sleep(0.1)
    while not taken or taken[-1].node != "n39":  # the newest comes in its turn
        await asyncio.sleep(0.05)
    spent = loop.time() - start
    redefined = [r for r in caplog.records if "definition of" in r.getMessage()]
    assert len(taken) <= spent / GRAPH_INTERVAL + 1, (len(taken), spent)
    assert 1 <= len(redefined) <= spent / REDEFINE_INTERVAL + 1, (len(redefined), spent)
    assert types.built[TYPE][0] == "int32 v39\n"  # built by the reader, off the loop
    assert types.load(TYPE, "msg", taken[-1].definitions)(v39=5).v39 == 5
    reader.close()


def test_a_definition_of_many_types_is_built_in_pieces() -> None:
    """A type whose definition chains 999 message types builds (50 at a time, each piece
    after those it uses; as one module the generator's ordering overflowed Python's stack),
    and every one of them is the robot's."""
    from msgs.dynamic import DELIMITER

    chain = "chain_msgs/C0 c\n" + "".join(
        f"{DELIMITER}\nMSG: chain_msgs/msg/C{i}\n"
        + (f"chain_msgs/C{i + 1} c\n" if i < 998 else "int32 x\n") for i in range(999))
    types = RobotTypes("chained", TypeLimits())
    top = types.load("chain_msgs/msg/Top", "msg", {"chain_msgs/msg/Top": chain})
    assert len(types.store) == 1000
    assert top._type == "chain_msgs/msg/Top"
    last: Any = types.store.lookup("chain_msgs/msg/C998")
    assert last(x=3).x == 3
