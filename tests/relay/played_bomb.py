"""Robots played on raw Zenoh, in their own processes, for the relay's message budget (issue
53, finding 2): one whose messages carry their send time, and one that puts valid messages
that cost a relay far more than their size to decode.

``python -m tests.relay.played_bomb ROUTER ROBOT MODE [MIB]`` joins ROUTER as robot ROBOT
(its ``@alive`` token, its graph document with :data:`BOMB`'s definition answered and put),
prints ``ready``, then:

- ``clock``: puts ``/steady`` std_msgs/msg/String at 20 Hz, the text its send time
  (``time.time()``), until stdin closes: a viewer on the same machine reads its latency;
- ``tiny`` and ``points``: for each line ``go`` on stdin puts one ``/bomb`` message of MIB
  MiB, then a small one (:func:`body` ``(3, 2)``), for a line ``small`` the small one alone,
  and prints ``put N``; ``tiny`` fills the large one with
  one-byte structs (the red team's bomb: ~230 bytes each decoded), ``points`` with
  ``geometry_msgs/Point`` (valid data that costs ~13 times its size decoded).
"""

from __future__ import annotations

import struct
import sys
import time

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta, Snapshot
from bridge_server.zenoh.link import ZenohOptions
from tests.relay.played_robot import STRING, _cdr_string, stdin_closed

BOMB = "bomb_msgs/msg/Bomb"
SEPARATOR = "=" * 80
DEFINITION = ("bomb_msgs/Tiny[] tiny\ngeometry_msgs/Point[] points\n"
              f"{SEPARATOR}\nMSG: bomb_msgs/Tiny\nuint8 x\n"
              f"{SEPARATOR}\nMSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n")
""":data:`BOMB`: a sequence of one-byte structs and one of points."""


def body(tiny: int, points: int) -> bytes:
    """A :data:`BOMB`'s CDR bytes: ``tiny`` one-byte structs (each ``x = 7``), ``points``
    points (their coordinates ``i / 3``)."""
    out = bytearray(b"\x00\x01\x00\x00")
    out += struct.pack("<I", tiny) + bytes([7]) * tiny
    out += bytes((4 - len(out)) % 4)
    out += struct.pack("<I", points)
    if points:
        out += bytes((4 - len(out)) % 8)  # doubles align to 8 from the header's end
        out += struct.pack(f"<{3 * points}d", *(i / 3 for i in range(3 * points)))
    return bytes(out)


def bomb_of(mode: str, mib: float) -> bytes:
    """The ``/bomb`` message ``mode`` puts: ``mib`` MiB of one-byte structs or of points."""
    size = int(mib * 2**20)
    return body(size, 0) if mode == "tiny" else body(0, size // 24)


def main() -> None:
    router, robot, mode = sys.argv[1:4]
    mib = float(sys.argv[4]) if len(sys.argv) > 4 else 4.0
    import zenoh

    session = zenoh.open(ZenohOptions(connect=[router]).config())
    graph = Snapshot(node="bomber", topics=[("/bomb", [BOMB]), ("/steady", [STRING])],
                     definitions={BOMB: DEFINITION}).encode()
    queryable = session.declare_queryable(
        f"{robot}/{keys.GRAPH}", lambda q: q.reply(q.key_expr, graph))
    token = session.liveliness().declare_token(f"{robot}/{keys.ALIVE}")
    session.put(f"{robot}/{keys.GRAPH}", graph)
    print("ready", flush=True)
    if mode == "clock":
        stop = stdin_closed()
        key = keys.key_of(robot, "/steady")
        n = 0
        while not stop.wait(0.05):
            n += 1
            session.put(key, _cdr_string(repr(time.time())),
                        attachment=Meta(type=STRING, epoch="e", seq=n).encode())
    else:
        key = keys.key_of(robot, "/bomb")
        big, small = bomb_of(mode, mib), body(3, 2)
        block = zenoh.CongestionControl.BLOCK
        n = 0
        for line in sys.stdin:
            for data in (big, small) if line.strip() == "go" else (small,):
                n += 1
                session.put(key, data, attachment=Meta(type=BOMB, epoch="e", seq=n).encode(),
                            congestion_control=block)
            print(f"put {n}", flush=True)
    token.undeclare()  # type: ignore[no-untyped-call]
    queryable.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
