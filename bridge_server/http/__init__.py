"""The bridge's plain-HTTP side on the websocket port: the status page and its
JSON (:mod:`.web`, :mod:`.web_access`, :mod:`.snapshot`, ``static/``), Prometheus
metrics (:mod:`.metrics`), several bridge workers behind one port
(:mod:`.workers`, :mod:`.peers`).
"""
