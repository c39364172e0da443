"""Why a connection attempt failed, said so that the user can act, and whether another
attempt could help: a refused handshake (a token, an origin, a certificate, a robot a relay
does not have), TLS spoken on one side only, a close for a policy violation. Used by
:class:`~roslibpy_lite.transports.websocket.WebSocketTransport`."""

from __future__ import annotations

import asyncio
import contextlib
import ssl
from urllib.parse import urlsplit

from websockets.asyncio.client import ClientConnection
from websockets.exceptions import InvalidHandshake, InvalidMessage, InvalidStatus

from rosbridge_core.protocol.constants import POLICY_VIOLATION
from rosbridge_core.protocol.ops import RELAY_HEADER

from ..exceptions import ConnectError, ConnectionClosed, NotAuthenticated, TLSError


def _relay_of(exc: BaseException) -> str | None:
    """The robot named by a relay's handshake answer (:data:`RELAY_HEADER`); ``None`` when
    no relay answered."""
    if not isinstance(exc, InvalidStatus):
        return None
    value: str | None = exc.response.headers.get(RELAY_HEADER)
    return value


def _server(url: str, exc: BaseException) -> str:
    """Who answered: "the relay at URL" (for robot R) or "the bridge at URL"."""
    robot = _relay_of(exc)
    if robot is None:
        return f"the bridge at {url}"
    return f"the relay at {url}" + (f" (robot {robot!r})" if robot else "")


def _answer(exc: InvalidStatus) -> str:
    """The server's own words in a refused handshake: its body's first line, shortened."""
    text = bytes(exc.response.body or b"").decode(errors="replace").strip()
    line = text.splitlines()[0] if text else ""
    return line if len(line) <= 200 else line[:200] + "..."


def _refusal(url: str, exc: BaseException) -> ConnectError | None:
    """A refusal that another attempt would only repeat: a token, an origin, a certificate."""
    if isinstance(exc, InvalidStatus):
        code = exc.response.status_code
        text = _answer(exc)
        if code == 429 and "authentication" in text:
            retry = exc.response.headers.get("Retry-After", "a few")
            return NotAuthenticated(
                f"{_server(url, exc)} refuses this address for now: too many failed "
                f"authentication attempts came from it; retry after {retry} s (this is no "
                "verdict on the token given)", refused=code)
        if code == 401:
            return NotAuthenticated(f"{_server(url, exc)} refused our token (HTTP {code}): "
                                    f"{text}", refused=code)
        if code == 403:
            return ConnectError(f"{_server(url, exc)} refused the connection (HTTP 403): {text}",
                                refused=code)
        return None
    if isinstance(exc, ssl.SSLCertVerificationError) and exc.verify_code in _NAME_MISMATCH:
        host = urlsplit(url).hostname
        return TLSError(
            f"TLS: the certificate of {url} is not valid for {host} ({exc.verify_message}): "
            f"its CA is trusted, but the certificate must list {host} in its subjectAltName; "
            "reissue it with that name or address (SECURITY.md: a private CA), or connect by "
            "a name it lists"
        )
    if isinstance(exc, ssl.SSLCertVerificationError):
        return TLSError(
            f"TLS: cannot verify the certificate of {url}: {exc.verify_message}; give the CA "
            "that signed it (ssl= an SSLContext or a CA file; --cafile or $ROSLIBPY_LITE_CAFILE "
            "on the command line)"
        )
    cause: BaseException | None = exc  # TLS 1.3 reports a missing client certificate late,
    while cause is not None and not isinstance(cause, ssl.SSLError):  # inside InvalidMessage
        cause = cause.__cause__ or cause.__context__
    if cause is not None and "CERTIFICATE_REQUIRED" in str(cause).upper():
        return TLSError(f"TLS: the bridge at {url} requires a client certificate (mutual TLS); "
                        "load one into the ssl context (SSLContext.load_cert_chain)")
    if url.startswith("wss://") and isinstance(exc, InvalidMessage) and isinstance(
        exc.__cause__, EOFError
    ):  # the server ended TLS right after the handshake: how TLS 1.3 refuses a client
        return TLSError(f"TLS: the bridge at {url} closed the connection before answering: it "
                        "probably requires a client certificate (mutual TLS); load one into "
                        "the ssl context (SSLContext.load_cert_chain)")
    return None

_NAME_MISMATCH = (62, 64)
"""OpenSSL's X509_V_ERR_HOSTNAME_MISMATCH and X509_V_ERR_IP_ADDRESS_MISMATCH."""


async def _plain_to_tls(url: str, exc: BaseException) -> ConnectError | None:
    """``ws://`` to a port that speaks TLS: the server hangs up on our plain request. Say so at
    once (one TLS handshake to the port tells) instead of retrying until ``open_timeout``."""
    if not (url.startswith("ws://") and isinstance(exc, InvalidMessage)
            and isinstance(exc.__cause__, EOFError)):
        return None
    parts = urlsplit(url)
    probe = ssl.create_default_context()
    probe.check_hostname, probe.verify_mode = False, ssl.CERT_NONE  # only: does it speak TLS?
    try:
        _, writer = await asyncio.wait_for(
            asyncio.open_connection(parts.hostname, parts.port or 80, ssl=probe), 2.0)
    except (OSError, TimeoutError, ssl.SSLError):
        return None
    # Only the question was asked: no TLS goodbye to wait for (a close() would leave it under
    # way, and the socket open, if the caller's loop ends with the error this returns).
    writer.transport.abort()
    with contextlib.suppress(Exception):
        await writer.wait_closed()
    return ConnectError(f"{url}: this port speaks TLS: use wss://{url.split('://', 1)[1]} "
                        "(with the CA that signed the bridge's certificate)")


def _closed_by_policy(url: str, ws: ClientConnection) -> ConnectionClosed | None:
    """The bridge closed with 1008 (policy violation): reconnecting would be refused again."""
    if ws.close_code != POLICY_VIOLATION:
        return None
    reason = ws.close_reason or "no reason given"
    if "authentication" in reason:
        return NotAuthenticated(f"the bridge at {url} closed the connection: {reason}")
    return ConnectionClosed(f"the bridge at {url} closed the connection (policy violation): "
                            f"{reason}")


def _tls_mismatch(url: str, exc: BaseException) -> bool:
    """A TLS handshake that failed: ``wss://`` to a plain server (retrying will not help)."""
    return url.startswith("wss://") and isinstance(exc, ssl.SSLError | ConnectionResetError)


def _not_found(url: str, exc: BaseException) -> ConnectError | None:
    """An HTTP 404 at the handshake: the robot the path names is not on the relay, or no
    websocket server is at that path. Said at once with the server's own words."""
    if not isinstance(exc, InvalidStatus) or exc.response.status_code != 404:
        return None
    return ConnectError(f"{_server(url, exc)} answered HTTP 404: {_answer(exc) or 'not found'}; "
                        f"{_hint(url, exc)}", refused=404)


def _hint(url: str, exc: BaseException) -> str:
    """What to check after a failed connection attempt."""
    if _tls_mismatch(url, exc):
        return ("the TLS handshake failed: if the bridge serves plain websockets, use "
                f"ws://{url.split('://', 1)[1]}")
    if _relay_of(exc) is not None:
        return ("check the robot's name in the URL's path, and that the robot's bridge is up "
                "and connected to the relay (wait_for_robot=True waits for a robot starting)")
    if isinstance(exc, InvalidHandshake):
        return "something answers there, but not as a websocket server: is the port right?"
    return "check that a rosbridge server is running there and the host and port are right"


def _why(exc: BaseException) -> str:
    if isinstance(exc, InvalidStatus):  # the status and the server's words, not only the code
        answer = _answer(exc)
        code = exc.response.status_code
        return f"HTTP {code} from {'the relay' if _relay_of(exc) is not None else 'the server'}" \
            + (f": {answer}" if answer else "")
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
