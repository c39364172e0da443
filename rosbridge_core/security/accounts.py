"""What all the connections of one principal, and of one address, hold together.

A connection's own bounds (``--max-message-size`` for the pieces of its incomplete fragmented
ops, ``--inbound-budget`` for the data it sent that waits) say nothing about a principal who
opens many connections: 30 connections with one token, from one address, each holding a
16 MB fragment held 525 MiB, and 1,000 of them (``--max-clients``) about 16 GB. So each
connection charges what it holds to an account of its principal (its token's) and one of its
address (:class:`Accounts`), for two kinds of holding (:data:`HELD_KINDS`):

``fragment_bytes``
    the pieces of incomplete ``fragment`` ops held for reassembly (rosbridge);
``inflight_bytes``
    received websocket data not yet handled: frames queued for the session, and the frames
    of a fragmented websocket message whose last frame has not come.

A charge that takes an account past its limit is refused with a text naming the kind, the
limit, whose account (the principal's: the per-token limit; the address's: the per-address
limit) and where to raise it; the caller drops what the charge was for (the fragmented op, or
the connection's partial websocket message with the connection) and the others go on.

The limits are set in the auth file (:func:`limits_from_table`)::

    [limits.per_principal]          # each principal, over all its connections
    fragment_bytes = 67108864
    inflight_bytes = 67108864

    [limits.per_address]            # each client address, over all its connections
    fragment_bytes = 67108864

    [roles.viewer]
    subscribe = ["*"]
    limits.fragment_bytes = 16777216    # each principal of this role (over the default)

0 means no limit. Without a value (and without an auth file) the default is
:data:`DEFAULT_MESSAGES` times ``--max-message-size`` (64 MiB at its default of 16 MiB): four
of the largest messages at once, whoever and from wherever they come.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from rosbridge_core.interfaces import BridgeError

__all__ = [
    "DEFAULT_MESSAGES",
    "FRAGMENT_BYTES",
    "HELD_KINDS",
    "INFLIGHT_BYTES",
    "Accounts",
    "CrossLimits",
    "Holder",
    "KindBudget",
    "LimitsError",
    "kinds_from_table",
    "limits_from_table",
]

FRAGMENT_BYTES = "fragment_bytes"
INFLIGHT_BYTES = "inflight_bytes"
HELD_KINDS = (FRAGMENT_BYTES, INFLIGHT_BYTES)
"""What a connection holds that is counted across connections (see the module docstring)."""

_WHAT = {FRAGMENT_BYTES: "fragment memory", INFLIGHT_BYTES: "in-flight bytes"}

DEFAULT_MESSAGES = 4
"""A principal's, and an address's, default limit of each kind: this many times the largest
message (``--max-message-size``)."""

_SCOPES = {"per_principal": "per-token", "per_address": "per-address"}


class LimitsError(BridgeError):
    """A ``limits`` table of the auth file is malformed (the text names the key)."""


def kinds_from_table(table: Any, where: str) -> dict[str, int]:
    """``{kind: bytes}`` of a table of :data:`HELD_KINDS` keys (``where`` names it in errors)."""
    if not isinstance(table, Mapping):
        raise LimitsError(f"{where} must be a table of {', '.join(HELD_KINDS)}")
    kinds: dict[str, int] = {}
    for key, value in table.items():
        if key not in HELD_KINDS:
            raise LimitsError(f"{where}: unknown limit {key!r} (known: {', '.join(HELD_KINDS)})")
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise LimitsError(f"{where}.{key} must be a whole number of bytes >= 0 "
                              f"(0: no limit), got {value!r}")
        kinds[key] = value
    return kinds


@dataclass(frozen=True)
class CrossLimits:
    """The auth file's ``[limits]``: per principal (a role's own ``limits`` wins) and per
    address; a kind not given takes the default (:data:`DEFAULT_MESSAGES`)."""

    per_principal: Mapping[str, int] = field(default_factory=dict)
    per_address: Mapping[str, int] = field(default_factory=dict)


def limits_from_table(table: Any, where: str) -> CrossLimits:
    """The :class:`CrossLimits` of the auth file's top-level ``limits`` table."""
    if not isinstance(table, Mapping):
        raise LimitsError(f"{where}: limits must be a table of per_principal and per_address")
    unknown = set(table) - set(_SCOPES)
    if unknown:
        raise LimitsError(f"{where}: unknown key(s) {sorted(unknown)} in limits "
                          f"(known: {', '.join(_SCOPES)})")
    return CrossLimits(
        **{scope: kinds_from_table(table[scope], f"{where}: limits.{scope}")
           for scope in _SCOPES if scope in table})


@dataclass
class _Account:
    held: dict[str, int] = field(default_factory=lambda: dict.fromkeys(HELD_KINDS, 0))
    holders: int = 0


class Accounts:
    """The accounts of every principal and every address of one bridge (or relay) process.

    ``limits(principal)`` gives ``(the principal's limits, the address limits)`` as
    configured now (a reload may change them); a kind missing from either takes the default.
    """

    def __init__(self, limits: Callable[[str | None], tuple[Mapping[str, int],
                                                            Mapping[str, int]]]) -> None:
        self._limits = limits
        self.message_size = 16 * 1024 * 1024
        """The largest message (``--max-message-size``): the defaults are multiples of it."""
        self._principals: dict[str, _Account] = {}
        self._addresses: dict[str, _Account] = {}

    def default(self) -> int:
        """The limit of a kind no configuration sets."""
        return DEFAULT_MESSAGES * self.message_size

    def holder(self, address: str) -> Holder:
        """A new connection's holder, charging the account of ``address``."""
        account = self._addresses.setdefault(address, _Account())
        account.holders += 1
        return Holder(self, address)

    def held(self, kind: str, *, principal: str | None = None,
             address: str | None = None) -> int:
        """What the connections of ``principal`` (or of ``address``) hold of ``kind`` now."""
        table, key = ((self._principals, principal) if principal is not None
                      else (self._addresses, address))
        account = table.get(key or "")
        return 0 if account is None else account.held[kind]

    def _refusal(self, kind: str, n: int, principal: str | None, address: str) -> str | None:
        """Why ``n`` more bytes of ``kind`` would pass a limit (``None``: they would not)."""
        mine, theirs = self._limits(principal)
        default = self.default()
        if principal is not None:
            limit = mine.get(kind, default)
            have = self._principals[principal].held[kind]
            if limit and have + n > limit:
                return (f"{_WHAT[kind]} of principal {principal}'s connections would pass the "
                        f"per-token limit ({kind} {limit} bytes)")
        limit = theirs.get(kind, default)
        have = self._addresses[address].held[kind]
        if limit and have + n > limit:
            return (f"{_WHAT[kind]} of the connections from {address} would pass the "
                    f"per-address limit ({kind} {limit} bytes)")
        return None

    def _add(self, kind: str, n: int, principal: str | None, address: str) -> None:
        if principal is not None:
            self._principals[principal].held[kind] += n
        self._addresses[address].held[kind] += n

    def _join(self, principal: str) -> None:
        self._principals.setdefault(principal, _Account()).holders += 1

    def _leave(self, principal: str | None, address: str | None) -> None:
        for table, key in ((self._principals, principal), (self._addresses, address)):
            if key is None:
                continue
            account = table[key]
            account.holders -= 1
            if account.holders <= 0:
                del table[key]


class Holder:
    """One connection's share of :class:`Accounts`: what it holds of each kind, charged to its
    address and (once it has proved one) its principal."""

    def __init__(self, accounts: Accounts, address: str) -> None:
        self.accounts = accounts
        self.address = address
        self.principal: str | None = None
        self.held = dict.fromkeys(HELD_KINDS, 0)
        self.closed = False

    def become(self, principal: str) -> None:
        """The connection proved to be ``principal``: what it holds is theirs from now on."""
        if self.closed or principal == self.principal:
            return
        accounts = self.accounts
        if self.principal is not None:
            for kind, n in self.held.items():
                accounts._principals[self.principal].held[kind] -= n
            accounts._leave(self.principal, None)
        accounts._join(principal)
        for kind, n in self.held.items():
            accounts._principals[principal].held[kind] += n
        self.principal = principal

    def budget(self, kind: str) -> KindBudget:
        """This holder's charges of one ``kind`` (what the protocol core's reassembly takes)."""
        return KindBudget(self, kind)

    def fragments(self) -> KindBudget:
        """What the protocol core's reassembly of ``fragment`` ops charges."""
        return self.budget(FRAGMENT_BYTES)

    def inflight(self) -> KindBudget:
        """What the connection's received, not yet handled websocket data charges."""
        return self.budget(INFLIGHT_BYTES)

    def take(self, kind: str, n: int) -> str | None:
        """Charge ``n`` bytes of ``kind``; or, if that would pass a limit, charge nothing and
        say which limit (the per-token or the per-address one) and where it is set."""
        if self.closed:
            return None
        why = self.accounts._refusal(kind, n, self.principal, self.address)
        if why is None:
            self.force(kind, n)
        return why

    def force(self, kind: str, n: int) -> None:
        """Charge ``n`` bytes of ``kind`` that are held already, whatever the limits say."""
        if not self.closed:
            self.held[kind] += n
            self.accounts._add(kind, n, self.principal, self.address)

    def over(self, kind: str) -> str | None:
        """Which limit what is charged of ``kind`` is past now (``None``: none)."""
        return None if self.closed else self.accounts._refusal(kind, 0, self.principal,
                                                               self.address)

    def give_back(self, kind: str, n: int) -> None:
        """Release ``n`` bytes of ``kind`` charged before."""
        if not self.closed:
            n = min(n, self.held[kind])
            self.held[kind] -= n
            self.accounts._add(kind, -n, self.principal, self.address)

    def close(self) -> None:
        """The connection ended: release everything it holds, and its place in the accounts."""
        if self.closed:
            return
        for kind, n in self.held.items():
            self.give_back(kind, n)
        self.closed = True
        self.accounts._leave(self.principal, self.address)


@dataclass(frozen=True)
class KindBudget:
    """One kind of a :class:`Holder`'s charges (a
    :class:`~rosbridge_core.protocol.frames.FragmentBudget` for ``fragment_bytes``)."""

    holder: Holder
    kind: str

    def take(self, n: int) -> str | None:
        """Charge ``n`` bytes, or say which limit they would pass (charging nothing)."""
        return self.holder.take(self.kind, n)

    def force(self, n: int) -> None:
        """Charge ``n`` bytes held already, whatever the limits say."""
        self.holder.force(self.kind, n)

    def over(self) -> str | None:
        """Which limit what is charged is past now (``None``: none)."""
        return self.holder.over(self.kind)

    def give_back(self, n: int) -> None:
        """Release ``n`` bytes charged before."""
        self.holder.give_back(self.kind, n)
