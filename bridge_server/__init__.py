"""A rosbridge v2 protocol server on rclpy (ROS 2 Jazzy from PyPI wheels).

Run it with ``python -m bridge_server --host 127.0.0.1 --port 9090`` (or the
``roslibpy-lite-bridge`` console script). Modules:

- :mod:`bridge_server.server`: the websocket server, one session per connection;
- :mod:`bridge_server.session`: what one client owns and how its ops run;
- :mod:`bridge_server.ros`: the rclpy node, its executor thread, shared entities;
- :mod:`bridge_server.rosapi`: the ``/rosapi/*`` introspection services;
- :mod:`bridge_server.convert` / :mod:`bridge_server.types`: message conversion
  and type names.
"""
