"""The robot's relay policy: what relays may ask of it (a role in the auth file's format,
``--relay-role``; :data:`DEFAULT_POLICY` without one), looked up at each request."""

from __future__ import annotations

from collections.abc import Callable

from bridge_server.zenoh.exporter.base import ExporterBase, log
from rosbridge_core.security.permissions import Role

__all__ = ["DEFAULT_POLICY", "RelayPolicy"]

DEFAULT_POLICY = Role.from_table("relays (default)", {"all": ["*"], "deny": {"take_over": ["*"]}})
"""What relays may ask of a robot that names no ``--relay-role``: every topic, service,
action and parameter, but not serving a name that a ROS node of the robot already serves
(two servers of one name would answer its callers by chance)."""


class RelayPolicy(ExporterBase):
    """The exporter's part that holds every request of a relay to the robot's policy."""

    policy: Callable[[], Role | None]
    """The role relays are held to, looked up at each request (an auth file read again on
    SIGHUP changes it at once); ``None``: the role is gone, and every request is refused."""
    policy_refused: dict[tuple[str, str], int]
    """Requests refused by the policy, by (capability, name): logged the first time."""

    def refusal(self, capability: str, name: str, relay: str | None = None) -> str | None:
        """Why the policy does not let relays (``relay``, where the request says which) use
        ``capability`` on ``name`` (``None``: they may). Logged at WARNING the first time for
        each (capability, name), then counted."""
        role = self.policy()
        if role is not None and role.allows(capability, name):
            return None
        which = f"role {role.name}" if role is not None else "its role, which is gone"
        why = (f"robot {self.robot}'s relay policy ({which}) does not let relays "
               f"{capability.replace('_', ' ')} {name}")
        key = (capability, name)
        self.policy_refused[key] = self.policy_refused.get(key, 0) + 1
        if self.policy_refused[key] == 1:
            log.warning("refused %s: %s", f"relay {relay}" if relay else "a relay", why)
        return why

    def _served_in_ros(self, key: str) -> bool:
        """Whether a ROS node other than the robot's own bridge serves ``key`` (the Graph's
        own count of servers, as the bridge's ownership rule asks it)."""
        return key not in self.served and bool(self.graph.other_servers(key))
