"""The bridge's plain-HTTP side on the websocket port: the status page and its
JSON (:mod:`.web`, :mod:`.web_access`, :mod:`.snapshot`, ``static/``), Prometheus
metrics (:mod:`.metrics`); the relay's pages build on them
(:mod:`bridge_server.zenoh.relay_web`). Several bridge workers behind one port are
supervised in :mod:`bridge_server.workers`.
"""
