"""The robot's side of the relay tier: its bridge's :class:`~rosbridge_core.graph.Graph` on Zenoh.

``roslibpy-lite-bridge --zenoh-connect tcp/router:7447 --robot r1`` runs one
:class:`Exporter` beside (or, with ``--no-websocket``, instead of) the websocket listener.
It dials out to the routers and offers the robot under ``r1/`` as :mod:`.keys` describes:

- a topic is subscribed in ROS only while some relay's demand token for it exists (an
  unwatched robot sends nothing); each message is put once, as the CDR bytes that came,
  however many relays and viewers watch it; a reliable topic's through an advanced
  publisher that keeps a bounded window of its last messages for relays whose link
  dropped (:mod:`.replay`: nothing lost in an outage within the window);
- a relay's publisher token makes a shared publisher of the Graph, and the messages put
  under ``@in/`` are published through it, CDR bytes as they came;
- service calls are queries, answered by the Graph's own ``call_service``;
- a goal is a query whose replies stream what the Graph's own action client reports
  (accepted, feedback, the result); a cancel is a query; a goal whose relay's ``@running``
  token goes (the relay died) is canceled, as the bridge cancels a leaving client's goals;
- a service a relay's client serves is served in ROS by the Graph's ``serve`` while its
  ``@serve`` token lives; each ROS call is a query to the relay, the reply answers it; the
  first relay's token keeps a name, and a later one (another relay's client) is refused
  with a put under ``@refused`` that its relay passes to the client (put again while the
  token lives: a put can reach a relay before the network routes it there);
- so is an action a relay's client serves (``serve_action``): each ROS goal is a query to
  the relay whose replies stream the goal's feedback and its end; a ROS cancel is a query;
- node parameters are queries run by the Graph's parameter methods;
- the graph (topics, services, nodes and the definitions of their types) is put when it
  changes, and answers queries.

What a relay may ask is the robot's decision: every request above is held to the robot's
relay policy, a role in the auth file's format (``--relay-role``; :data:`DEFAULT_POLICY`
without one: everything but taking over a name a ROS node serves). A refused call, goal,
parameter or served name is answered with the reason; a refused topic is logged and left
unwatched or unpublished. A relay with a valid certificate, compromised or misconfigured,
can do no more than the policy lets it.

It talks to ROS only through the Graph protocol, so it knows nothing of rclpy. Zenoh calls
back on its own threads: every callback crosses to the event loop with
``call_soon_threadsafe`` and the Graph is used there only.

One module per job, as :mod:`rosbridge_core.session` has: :mod:`.exporter` (the
:class:`Exporter` and its life), :mod:`.presence` (the robot's name and uplink),
:mod:`.policy` (the relay policy), :mod:`.topics` (demand-driven topics),
:mod:`.publishing` (relays' publishers), :mod:`.services` (service calls), :mod:`.served`
(services and actions relays' clients serve), :mod:`.actions` (relays' goals),
:mod:`.parameters`, :mod:`.graph` (the graph snapshot) and :mod:`.base` (what they share).
"""

from bridge_server.zenoh.exporter.exporter import DIAL_WARNING, SNAPSHOT_INTERVAL, Exporter
from bridge_server.zenoh.exporter.policy import DEFAULT_POLICY
from bridge_server.zenoh.exporter.presence import (
    CLAIM_RECHECK,
    CLAIM_WAIT,
    RETURN_LEASES,
    RETURN_POLL,
)
from bridge_server.zenoh.exporter.publishing import UNHELD_PUBLISHER_WAIT
from bridge_server.zenoh.exporter.served import REFUSAL_REPEAT, SERVED_CALL_WAIT

__all__ = ["CLAIM_RECHECK", "CLAIM_WAIT", "DEFAULT_POLICY", "DIAL_WARNING", "REFUSAL_REPEAT",
           "RETURN_LEASES", "RETURN_POLL", "SERVED_CALL_WAIT", "SNAPSHOT_INTERVAL",
           "UNHELD_PUBLISHER_WAIT", "Exporter"]
