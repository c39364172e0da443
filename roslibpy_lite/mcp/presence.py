"""Whether the robot behind a relay is away, as the relay says it, for answers an agent can
act on: a tool that failed while the robot is away says so (not only "no answer within the
timeout"), and the graph tools say their answer is the relay's last view, with its age.

A relay tells its clients in status ops: ``robot <name> went away: ...`` (a warning) when
the robot's link drops and ``robot <name> is back: ...`` (info) when it returns
(``bridge_server/zenoh/relay.py``). A bridge that is the robot never says either.
"""

from __future__ import annotations

import time
from typing import Any

from .listing import cut_value

__all__ = ["GRAPH_TOOLS", "Presence"]

GRAPH_TOOLS = frozenset({"list_topics", "list_services", "list_actions", "list_nodes",
                         "list_params"})
"""The tools whose answer is the graph as the relay last saw it."""

_AWAY, _BACK = " went away", " is back"


class Presence:
    """The robot's presence as the relay last told it (subscribed to ``ros``' status ops)."""

    def __init__(self, ros: Any) -> None:
        self._since: float | None = None
        self._words = ""
        ros.on_status(self._status)

    def _status(self, op: Any) -> None:
        text = str(op.msg)
        if op.level == "warning" and text.startswith("robot ") and _AWAY in text:
            self._since, self._words = time.monotonic(), text
        elif op.level == "info" and text.startswith("robot ") and _BACK in text:
            self._since = None

    def away(self) -> str | None:
        """What to tell the agent while the robot is away (``None``: it is not)."""
        if self._since is None:
            return None
        return (f"the robot is away ({time.monotonic() - self._since:.0f} s ago the relay said: "
                f"{cut_value(self._words, 300)})")

    def stale(self) -> str | None:
        """The note a graph answer carries while the robot is away."""
        away = self.away()
        return None if away is None else f"{away}; this graph is the relay's last view of it"
