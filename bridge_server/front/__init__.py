"""The bridge's front: what faces the network.

- :mod:`bridge_server.front.server`: :class:`~bridge_server.front.server.Bridge`, the
  websocket listener (one session per connection, the subprotocol choice) and what its
  sessions share;
- :mod:`bridge_server.front.websocket`: the sessions' link over websockets
  (:class:`~bridge_server.front.websocket.WebSocketLink`), the frame fast path and the
  inbound byte budget: the only code that relies on websockets' internals.

Nothing is imported here, so a module below the front may name the link's module without
loading the listener.
"""
