"""What a bridge's sessions need of its security, with no network in it: the auth file and
its principals, the failed-attempt lock-out, what each principal and address may hold, the
``auth`` op's check and a gate per session.

:class:`Authority` is all of it that a session over any link uses (the in-memory server's, and
MockRos's); the websocket front's :class:`bridge_server.front.handshake.Security` adds TLS,
the handshake's checks and the connection counts on top.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping

from rosbridge_core.security.accounts import Accounts
from rosbridge_core.security.auth import (
    AuthConfig,
    AuthFileError,
    FailureTracker,
    Principal,
    load_auth_file,
)
from rosbridge_core.security.gate import Gate, Guarded
from rosbridge_core.security.options import SecurityConfig

__all__ = ["Authority"]

log = logging.getLogger("bridge_server.security")


class Authority:
    """The security configuration a bridge's sessions share, and the state kept across them."""

    def __init__(self, config: SecurityConfig) -> None:
        self.config = config
        self.auth: AuthConfig | None = (
            load_auth_file(config.auth_file) if config.auth_file else None
        )
        self.failures = FailureTracker()
        self.accounts = Accounts(self._held_limits)  # per principal and per address

    def reload_auth(self, gates: Iterable[Gate]) -> bool:
        """Read the auth file again; True if it loaded (or there is none).

        Each session keeps its principal if the new file still has it with the same token,
        and gets its role as the file now defines it; a session whose principal was removed
        or got a new token is closed (1008, "credentials revoked"). A file that does not
        load changes nothing: the error is logged and the running configuration stays.
        """
        c = self.config
        if c.auth_file:
            try:
                auth = load_auth_file(c.auth_file)
            except AuthFileError as exc:
                log.error("reloading the auth file failed, the old one stays: %s", exc)
                return False
            self.auth = auth
            now = {(p.name, p.salt, p.digest): p for p in auth.principals}
            revoked = ended = 0
            for gate in gates:
                old = gate.principal
                if old is None:
                    continue
                new = now.get((old.name, old.salt, old.digest))
                if new is None:
                    revoked += 1
                    gate.close(f"credentials revoked: principal {old.name} is no longer "
                               "in the auth file with that token")
                else:
                    gate.principal, gate.role = new, new.role
                    ended += gate.session.recheck_grants()
            log.info("reloaded the auth file %s: %d principal(s), %d role(s); %d session(s) "
                     "closed as revoked, %d grant(s) the new roles no longer allow ended",
                     c.auth_file, len(auth.principals), len(auth.roles), revoked, ended)
        return True

    def _held_limits(self, principal: str | None
                     ) -> tuple[Mapping[str, int], Mapping[str, int]]:
        """What ``principal``, and an address, may hold as the auth file says now."""
        if self.auth is None:
            return {}, {}
        return self.auth.limits_of(principal)

    def verify_auth_op(self, address: str, mac: str, who: str) -> Principal | str:
        """The principal of an ``auth`` op's token (``mac``) from ``address``, or why it is
        refused (locked out; a wrong token, counted toward the lock-out). ``who`` names the
        connection in the log (never the token)."""
        assert self.auth is not None
        locked = self.locked_out(address)
        if locked is not None:  # connections opened before the lock-out get no guess either
            log.warning("%s: auth op from %s refused: locked out after failed attempts", who,
                        address)
            return locked[0]
        principal = self.auth.verify(mac)
        if principal is None:
            count = self.failures.failed(address)
            log.warning("%s: auth op from %s with a wrong token (failure %d)", who, address,
                        count)
            return "authentication failed: the auth op's token (mac) is not valid"
        self.failures.succeeded(address)
        return principal

    def locked_out(self, address: str) -> tuple[str, str] | None:
        """Why ``address`` may not try a token now, and its ``Retry-After`` (``None``: it may)."""
        wait = self.failures.locked_for(address)
        if wait <= 0:
            return None
        return (f"too many failed authentication attempts from {address}; retry in {wait:.0f} s",
                str(max(1, round(wait))))

    def gate(self, session: Guarded, rosapi: Mapping[str, tuple[str, ...]] | None = None
             ) -> Gate:
        """The gate for a new session (``rosapi``: as :class:`~.gate.Gate` takes it)."""
        return Gate(self, session, session.link.principal, rosapi)
