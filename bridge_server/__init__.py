"""A rosbridge v2 protocol server on rclpy (ROS 2 Jazzy from PyPI wheels).

Run it with ``python -m bridge_server --host 127.0.0.1 --port 9090`` (or the
``roslibpy-lite-bridge`` console script). Packages, by job:

- :mod:`bridge_server.front`: what faces the network: the websocket listener, one session
  per connection (``front/server.py``), and the sessions' link over websockets with the
  frame fast path (``front/websocket.py``);
- :mod:`rosbridge_core.session`: what one client owns and how its ops run (the op
  groups, outbox, ownership, resume, the ``/rosapi/*`` services);
- :mod:`bridge_server.rclpy_graph`: the ROS side on rclpy (the node, its executor
  thread and readers, shared entities, actions, message conversion, type names);
- :mod:`rosbridge_core.codec`: message encodings that need no ROS (JSON from CDR, the
  ``publish`` envelopes);
- :mod:`bridge_server.zenoh`: the relay tier (the robot's exporter, the relay's Graph,
  ``roslibpy-lite-relay``), without ROS;
- :mod:`bridge_server.http`: the status page, metrics, health, the relay's pages;
- :mod:`bridge_server.workers`: ``--workers``, several bridge processes behind one port;
- :mod:`rosbridge_core.security`: handshake, gate, credentials, roles, names.
"""
