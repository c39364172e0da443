"""Authentication, roles and limits as a bridge's sessions meet them, with no network in it.

One module per job: :mod:`.options` (the command line, :class:`SecurityConfig`),
:mod:`.auth` (the auth file, principals, tokens), :mod:`.permissions` (what a role may
do), :mod:`.accounts` (what a principal and an address may hold), :mod:`.authority`
(:class:`Authority`: what every session of one bridge shares: the auth file, the lock-out,
the ``auth`` op's check, a gate per session), :mod:`.gate` (:class:`Gate`: per session,
consulted before each frame and each op: the ``auth`` op, the op rate, name validity, the
role's permissions and the caps on subscriptions, publishers and services),
:mod:`.names`, :mod:`.credentials` (address and token of a request) and
:mod:`.redaction` (tokens out of logs).

The websocket front builds on it: :class:`bridge_server.front.handshake.Security` adds
TLS, the handshake's checks (origin, client limits, a token in a header or the query) and
SIGHUP's reload of the certificates; :mod:`bridge_server.front.websocket` the inbound byte
budget per connection. The in-memory server (:mod:`rosbridge_core.memory.server`) uses
:class:`Authority` alone.

Refusals answer the offender and nobody else: a ``status`` error naming the op, the name
and the role for a forbidden op, and a close with code 1008 (policy violation) and a
reason for a failed ``auth`` op or an op flood. Tokens never reach a log line or an error
text (:class:`RedactTokens` also scrubs other libraries' log lines).
"""

from __future__ import annotations

from rosbridge_core.security.authority import Authority
from rosbridge_core.security.credentials import is_loopback
from rosbridge_core.security.gate import POLICY_VIOLATION, PRE_AUTH_FRAME_LIMIT, Gate
from rosbridge_core.security.options import (
    SecurityConfig,
    add_arguments,
    check_readable,
    config_from_args,
    exposure_refusal,
    parse_origins,
    user_name,
)
from rosbridge_core.security.redaction import RedactTokens, install_log_redaction, redact

__all__ = [
    "POLICY_VIOLATION",
    "PRE_AUTH_FRAME_LIMIT",
    "Authority",
    "Gate",
    "RedactTokens",
    "SecurityConfig",
    "add_arguments",
    "check_readable",
    "config_from_args",
    "exposure_refusal",
    "install_log_redaction",
    "is_loopback",
    "parse_origins",
    "redact",
    "user_name",
]
