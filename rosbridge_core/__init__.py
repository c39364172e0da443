"""The rosbridge v2 core that both ends use: the lowest floor above ``msgs``.

It imports ``msgs`` and itself only, never the client (``roslibpy_lite``) or the server
(``bridge_server``); ``tests/core/test_floors.py`` holds that. From the bottom up:

- :mod:`rosbridge_core.protocol`: the protocol, sans-I/O: ops, frames (JSON, CBOR,
  fragments), keepalive, errors, goal status;
- :mod:`rosbridge_core.interfaces` (type names, the error roots), :mod:`rosbridge_core.graph`
  (the ports a ROS side implements), :mod:`rosbridge_core.typedefs`, :mod:`rosbridge_core.codec`
  (encodings that need no ROS), :mod:`rosbridge_core.counters` (a bridge's event counters);
- :mod:`rosbridge_core.security`: authentication, roles and limits as sessions meet them;
- :mod:`rosbridge_core.session`: one client's rosbridge session over a link and a Graph;
- :mod:`rosbridge_core.memory`: a whole ROS graph in memory and a server of sessions over
  in-memory links (what :class:`roslibpy_lite.MockRos` runs).

The websocket front, the rclpy Graph, the relay and the status pages are the server's
(``bridge_server``); the user API is the client's (``roslibpy_lite``).
"""

__version__ = "0.1.0"
"""The version of the one distribution (roslibpy-lite) these packages ship in: pyproject.toml
reads it from here, the client re-exports it, the bridge's status pages show it."""
