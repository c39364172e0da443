"""Robots played on raw Zenoh, in their own processes, for the relay's per-robot time bounds
(issue 53, findings 5 and 6): a well-behaved one whose messages carry their send time, and
two that cost a relay time without breaking any byte bound.

``python -m tests.relay.played_costly ROUTER ROBOT MODE`` joins ROUTER as robot ROBOT (its
``@alive`` token, its graph document answered and put), prints ``ready``, waits for a line
on stdin, then plays MODE until stdin closes:

- ``clock``: ``/steady`` std_msgs/msg/String at 20 Hz, the text its send time
  (``time.time()``): a viewer on the same machine reads its latency from it;
- ``redefine``: four graph documents a second, each defining ``evil_msgs/msg/Big`` anew
  (two ~190 KB definitions in turn, each with :data:`DEPENDENCIES` message types), and
  ``/evil`` messages of that type at 20 Hz, so a relay watching ``/evil`` reads each new
  definition;
- ``graphs``: ten 3.4 MB graph documents a second (90,000 topics), each different from the
  one before.
"""

from __future__ import annotations

import sys
import threading
import time

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta, Snapshot
from bridge_server.zenoh.link import ZenohOptions
from tests.relay.played_robot import STRING, _cdr_string

BIG = "evil_msgs/msg/Big"
DEPENDENCIES = 650
"""Message types in each of the redefining robot's definitions of :data:`BIG`."""
TOPICS = 90_000
"""Topics in each of the ``graphs`` robot's documents."""


def definition(variant: str) -> str:
    """A ~190 KB definition of :data:`BIG`: one float64 of its own, and
    :data:`DEPENDENCIES` message types of ten fields each after it (built by a relay, used
    by nothing), named after ``variant`` so that two variants differ."""
    deps = "".join(
        "=" * 80 + f"\nMSG: evil_msgs/Dep{i}\n"
        + "".join(f"float64 {variant}_{j}_longer\n" for j in range(10))
        for i in range(DEPENDENCIES))
    return "float64 x\n" + deps


def _graph(i: int) -> bytes:
    """A 3.4 MB graph document of :data:`TOPICS` topics, its names made of ``i``."""
    return Snapshot(node="costly", topics=[
        (f"/t{i}/tp{n}", ["std_msgs/msg/String"]) for n in range(TOPICS)]).encode()


def main() -> None:
    router, robot, mode = sys.argv[1:4]
    import zenoh

    session = zenoh.open(ZenohOptions(connect=[router]).config())
    graph = [Snapshot(node="costly").encode()]
    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, graph[0])
        query.drop()  # type: ignore[no-untyped-call]

    queryable = session.declare_queryable(f"{robot}/{keys.GRAPH}", answer)
    token = session.liveliness().declare_token(f"{robot}/{keys.ALIVE}")
    session.put(f"{robot}/{keys.GRAPH}", graph[0])
    docs: list[bytes] = []
    if mode == "redefine":
        docs = [Snapshot(node="costly", topics=[("/evil", [BIG])],
                         definitions={BIG: definition(v)}).encode() for v in ("a", "b")]
        graph[0] = docs[0]
        session.put(f"{robot}/{keys.GRAPH}", docs[0])
    elif mode == "graphs":
        docs = [_graph(i) for i in range(4)]
    print("ready", flush=True)
    sys.stdin.readline()
    stop = threading.Event()

    def until_stdin_closes() -> None:
        sys.stdin.read()
        stop.set()

    threading.Thread(target=until_stdin_closes, daemon=True).start()
    block = zenoh.CongestionControl.BLOCK
    n = 0
    period = {"clock": 0.05, "redefine": 0.05, "graphs": 0.1}[mode]
    while not stop.wait(period):
        n += 1
        if mode == "clock":
            session.put(keys.key_of(robot, "/steady"), _cdr_string(repr(time.time())),
                        attachment=Meta(type=STRING, epoch="e", seq=n).encode())
        elif mode == "redefine":
            if n % 5 == 0:  # four a second, the two definitions in turn
                graph[0] = docs[(n // 5) % 2]
                session.put(f"{robot}/{keys.GRAPH}", graph[0], congestion_control=block)
            session.put(keys.key_of(robot, "/evil"), b"\x00\x01\x00\x00" + bytes(8),
                        attachment=Meta(type=BIG, epoch="e", seq=n).encode())
        else:
            session.put(f"{robot}/{keys.GRAPH}", docs[n % len(docs)], congestion_control=block)
    token.undeclare()  # type: ignore[no-untyped-call]
    queryable.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
