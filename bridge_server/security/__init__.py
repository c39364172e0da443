"""TLS, authentication, origins and limits: everything between a socket and a session.

One module per job: :mod:`.options` (the command line), :mod:`.credentials` (address and
token of a request), :mod:`.handshake` (:class:`Security`: TLS, reload, the handshake),
:mod:`.gate` (:class:`Gate`: per session) and :mod:`.redaction` (tokens out of logs); the
connection class it serves with (the inbound byte budget, the frame fast path, the
sessions' link) is :mod:`bridge_server.front.websocket`, the only code that relies on websockets'
private internals. Who may see the plain-HTTP routes is
:class:`bridge_server.http.web.WebAccess`.

One :class:`Security` per bridge holds the configuration (:class:`SecurityConfig`,
set from the command line) and does three jobs:

* at the handshake (:meth:`Security.process_request`, called from the server's
  ``process_request`` hook after any plain-HTTP routes): the browser origin,
  the client limits (in all and per address), the failed-attempt lock-out and
  a token from an ``Authorization: Bearer`` header or a ``?token=`` query
  parameter. A wrong token is HTTP 401; no token at all, when the auth file
  requires one, lets the connection open but its first op must be ``auth``
  (what browsers and roslib can send);
* per connection (:class:`BridgeConnection`): a byte budget for inbound data
  waiting to be handled, per connection and in all; over it, the bridge stops
  reading that socket (TCP pushes back on the sender) until it has caught up;
* per session (:class:`Gate`, consulted by the session before each frame and
  each op): the ``auth`` op, the op rate, name validity, the role's
  permissions and the caps on subscriptions, publishers and services.

:meth:`Security.reload` (SIGHUP) reads the certificate files and the auth file
again: new handshakes use them, sessions get their principal's role as now
defined, and sessions of a removed principal are closed.

Refusals answer the offender and nobody else: an HTTP status with a one-line
text at the handshake, a ``status`` error naming the op, the name and the role
for a forbidden op, and a close with code 1008 (policy violation) and a reason
for a failed ``auth`` op or an op flood. Tokens never reach a log line or an
error text (:class:`RedactTokens` also scrubs other libraries' log lines).
"""

from __future__ import annotations

from ..front.websocket import BridgeConnection, WebSocketLink, check_websockets_internals
from .credentials import is_loopback
from .gate import POLICY_VIOLATION, PRE_AUTH_FRAME_LIMIT, Gate
from .handshake import Security
from .options import (
    SecurityConfig,
    add_arguments,
    check_readable,
    config_from_args,
    exposure_refusal,
    parse_origins,
    user_name,
)
from .redaction import RedactTokens, install_log_redaction, redact

__all__ = [
    "POLICY_VIOLATION",
    "PRE_AUTH_FRAME_LIMIT",
    "BridgeConnection",
    "Gate",
    "RedactTokens",
    "Security",
    "SecurityConfig",
    "WebSocketLink",
    "add_arguments",
    "check_readable",
    "check_websockets_internals",
    "config_from_args",
    "exposure_refusal",
    "install_log_redaction",
    "is_loopback",
    "parse_origins",
    "redact",
    "user_name",
]
