"""A robot played on raw Zenoh, in its own process, for a relay's tests: a well-behaved one
(a steady topic), or a malicious one (floods, oversized or nested graph documents, bad CDR).

``python -m tests.relay.played_robot ROUTER ROBOT MODE [SECONDS]`` joins ROUTER as robot
ROBOT (its liveliness token, its graph document answered and put), prints ``ready``, waits
for a line on stdin, then plays MODE and prints ``done N`` (N: what it put):

- ``steady``: ``/steady`` std_msgs/msg/String at 20 Hz (the text is the message's index),
  until stdin closes;
- ``flood``: ``/flood`` Float64MultiArray messages of 1000 values (8 KiB, costly to write
  as JSON) as fast as it can for SECONDS;
- ``graphs``: one graph document nested 100 000 deep, ten 20 MB ones over SECONDS, then 50
  small ones at once (the last names the node ``played49``);
- ``bad``: 200 messages on ``/flood`` whose CDR bytes are no String, then a String whose
  stamp is 2**70 ns.
"""

from __future__ import annotations

import sys
import threading
import time

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta, Snapshot
from bridge_server.zenoh.link import ZenohOptions

STRING = "std_msgs/msg/String"
ARRAY = "std_msgs/msg/Float64MultiArray"


def _cdr_string(text: str) -> bytes:
    """A std_msgs/msg/String's CDR bytes (little-endian encapsulation)."""
    data = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + len(data).to_bytes(4, "little") + data


def stdin_closed() -> threading.Event:
    """An event set once the test closes this process's standard input (its way to say
    stop), read by a daemon thread."""
    stop = threading.Event()

    def until_stdin_closes() -> None:
        sys.stdin.read()
        stop.set()

    threading.Thread(target=until_stdin_closes, daemon=True).start()
    return stop


def main() -> None:
    router, robot, mode = sys.argv[1:4]
    seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 3.0
    import zenoh

    session = zenoh.open(ZenohOptions(connect=[router]).config())
    graph = Snapshot(node="played").encode()
    queryable = session.declare_queryable(
        f"{robot}/{keys.GRAPH}", lambda q: q.reply(q.key_expr, graph))
    token = session.liveliness().declare_token(f"{robot}/{keys.ALIVE}")
    session.put(f"{robot}/{keys.GRAPH}", graph)
    print("ready", flush=True)
    sys.stdin.readline()
    n = 0
    if mode == "steady":
        stop = stdin_closed()
        key = keys.key_of(robot, "/steady")
        while not stop.wait(0.05):
            n += 1
            session.put(key, _cdr_string(str(n)),
                        attachment=Meta(type=STRING, epoch="e", seq=n).encode())
    elif mode == "flood":
        from msgs import cdr
        from msgs.std_msgs.msg import Float64MultiArray

        key = keys.key_of(robot, "/flood")
        body = cdr.encode(Float64MultiArray(data=[i / 7 for i in range(1000)]))
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            n += 1
            session.put(key, body, attachment=Meta(type=ARRAY, epoch="e", seq=n).encode())
    elif mode == "graphs":
        # Every document is put blocking, not dropped by this robot's own Zenoh when its
        # queue is full (a loaded machine): the relay counts each of them, whatever the load.
        # The deep one first: the big ones after it are dropped before they are queued, so
        # nothing replaces it for SECONDS and it is read (and counted) whatever the load.
        block = zenoh.CongestionControl.BLOCK
        session.put(f"{robot}/{keys.GRAPH}", b"[" * 100_000 + b"]" * 100_000,
                    congestion_control=block)
        n += 1
        big = b'{"definitions": {"a/msg/B": "' + b"x" * (20 * 1000 * 1000) + b'"}}'
        for _ in range(10):
            n += 1
            session.put(f"{robot}/{keys.GRAPH}", big, congestion_control=block)
            time.sleep(seconds / 10)
        for i in range(50):  # faster than the relay reads them: the newest is kept
            n += 1
            session.put(f"{robot}/{keys.GRAPH}", Snapshot(node=f"played{i}").encode(),
                        congestion_control=block)
    elif mode == "bad":
        key = keys.key_of(robot, "/flood")
        for _ in range(200):
            n += 1
            session.put(key, b"\x00\x01\x00\x00\xff\xff\xff\x7f",  # a string of 2 GB
                        attachment=Meta(type=STRING, epoch="e", seq=n).encode())
        n += 1  # and a good one whose stamp no encoding holds
        session.put(key, _cdr_string("late"),
                    attachment=Meta(type=STRING, stamp_ns=1 << 70, epoch="e", seq=n).encode())
    print(f"done {n}", flush=True)
    if mode != "steady":
        sys.stdin.read()  # stay on the network until told to go
    token.undeclare()  # type: ignore[no-untyped-call]
    queryable.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
