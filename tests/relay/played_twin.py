"""A robot played on raw Zenoh, in its own process, that says its Zenoh session in each put
as the exporter does (``Meta.zid``): the holder of a name, or a twin that announces the same
name after it and, refused, puts all the same (issue 53, finding 11).

``python -m tests.relay.played_twin ROUTER ROBOT ROLE`` joins ROUTER as robot ROBOT: it
declares its ``@claim`` and ``@alive`` tokens, prints ``ready``, then puts ``/steady``
std_msgs/msg/String at 20 Hz (the text is ROLE and the message's index) until stdin
closes. ``ROLE`` ``twin`` first waits until another session holds the name.
"""

from __future__ import annotations

import sys
import threading

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta
from bridge_server.zenoh.link import ZenohOptions
from tests.relay.played_robot import STRING, _cdr_string


def main() -> None:
    router, robot, role = sys.argv[1:4]
    import zenoh

    session = zenoh.open(ZenohOptions(connect=[router]).config())
    zid = str(session.zid())
    if role == "twin":  # the holder's token first: this one is refused
        held = threading.Event()
        watch = session.liveliness().declare_subscriber(
            f"{robot}/{keys.ALIVE}/*", lambda s: held.set(), history=True)
        if not held.wait(30):
            raise SystemExit("no robot holds the name")
        watch.undeclare()  # type: ignore[no-untyped-call]
    live = session.liveliness()
    tokens = [live.declare_token(keys.claim_key(robot, zid)),
              live.declare_token(keys.alive_key(robot, zid))]
    print("ready", flush=True)
    stop = threading.Event()

    def until_stdin_closes() -> None:
        sys.stdin.read()
        stop.set()

    threading.Thread(target=until_stdin_closes, daemon=True).start()
    key = keys.key_of(robot, "/steady")
    n = 0
    while not stop.wait(0.05):
        n += 1
        session.put(key, _cdr_string(f"{role} {n}"),
                    attachment=Meta(type=STRING, epoch=role, seq=n, zid=zid).encode())
    for token in tokens:
        token.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
