"""A robot played on raw Zenoh, in its own process, that says its Zenoh session in each put
as the exporter does (``Meta.zid``): the holder of a name, or a twin that announces the same
name after it and, refused, puts all the same (issue 53, finding 11).

``python -m tests.relay.played_twin ROUTER ROBOT ROLE`` joins ROUTER as robot ROBOT: it
declares its ``@claim`` and ``@alive`` tokens and puts and answers its graph document
(listing ``/steady``, the twin's ``/twin_topic``), prints ``ready``, then puts ``/steady``
std_msgs/msg/String at 20 Hz (the text is ROLE and the message's index), the twin its
graph document again twice a second, until stdin closes. ``ROLE`` ``twin`` first waits
until another session holds the name.
"""

from __future__ import annotations

import sys
import threading

from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Meta, Snapshot
from bridge_server.zenoh.link import ZenohOptions
from tests.relay.played_robot import STRING, _cdr_string, stdin_closed

TOPICS = {"holder": "/steady", "twin": "/twin_topic"}
"""The topic each one's graph document lists."""


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
    graph = Snapshot(node=role, topics=[(TOPICS[role], [STRING])]).encode()
    said = zid.encode()  # the session, as the exporter says it

    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, graph, attachment=said)
        query.drop()  # type: ignore[no-untyped-call]

    queryable = session.declare_queryable(f"{robot}/{keys.GRAPH}", answer)
    live = session.liveliness()
    tokens = [live.declare_token(keys.claim_key(robot, zid)),
              live.declare_token(keys.alive_key(robot, zid))]
    session.put(f"{robot}/{keys.GRAPH}", graph, attachment=said)
    print("ready", flush=True)
    stop = stdin_closed()
    key = keys.key_of(robot, "/steady")
    n = 0
    while not stop.wait(0.05):
        n += 1
        session.put(key, _cdr_string(f"{role} {n}"),
                    attachment=Meta(type=STRING, epoch=role, seq=n, zid=zid).encode())
        if role == "twin" and n % 10 == 0:  # its graph too, twice a second
            session.put(f"{robot}/{keys.GRAPH}", graph, attachment=said)
    for token in tokens:
        token.undeclare()  # type: ignore[no-untyped-call]
    queryable.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
