"""The relay tier on Zenoh (issue 26): the robot dials out, relays without ROS serve clients.

- :mod:`.keys`: the wire contract (keys and payloads) between the two sides;
- :mod:`.link`: the Zenoh session from command-line options (endpoints, TLS);
- :mod:`.exporter`: the robot's side, its bridge's Graph offered on Zenoh;
- :mod:`.graph`: the relay's side, a :class:`~rosbridge_core.graph.Graph` of one robot
  read from Zenoh;
- :mod:`.relay`: ``roslibpy-lite-relay``, the bridge's sessions served over those Graphs.

Nothing here imports ROS.
"""
