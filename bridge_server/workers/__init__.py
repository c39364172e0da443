"""``--workers N``: several bridge processes behind one port, and how they work together.

- :mod:`.supervisor`: the supervisor process (no rclpy) that reserves the port, starts,
  watches and restarts the workers, and relays their logs;
- :mod:`.peers`: how workers see each other (each serves its snapshot on a unix socket,
  and reads the others' for the status page and ``/metrics``).

A session resume that reaches another worker is forwarded to the worker that holds the
session by the front (:mod:`bridge_server.front.forward`).
"""
