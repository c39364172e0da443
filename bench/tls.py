"""What TLS costs: the same scenarios over ws:// and over wss:// (``--scenario tls``).

Certificates are made for the run with ``trustme`` (a dev dependency). The
scenarios are the ordinary ones from ``bench/run.py`` (ROS -> client step
search of small strings, call_service round trips, 640x480 images as CBOR),
run once against a plain bridge and once against a bridge with ``--certfile``;
the result puts the two side by side. Nothing here asserts anything about time.
"""

from __future__ import annotations

import dataclasses
import ssl
import tempfile
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from bench.harness import Ctx, trust_tls

__all__ = ["make_certs", "tls_scenario"]


def make_certs() -> str:
    """A server certificate for 127.0.0.1 (key and chain in one PEM); trust it on the client."""
    import trustme

    ca = trustme.CA()
    path = Path(tempfile.mkdtemp(prefix="bench-tls-")) / "server.pem"
    ca.issue_cert("127.0.0.1").private_key_and_cert_chain_pem.write_to_path(str(path))
    client = ssl.create_default_context()
    ca.configure_trust(client)
    trust_tls(client)
    return str(path)


Scenario = Callable[["Ctx"], Awaitable[dict[str, Any]]]


async def tls_scenario(
    ctx: Ctx, ros_to_client: Scenario, service: Scenario, image: Scenario
) -> dict[str, Any]:
    """The given ros_to_client, service and image scenarios over ws:// and over wss://."""
    certfile = make_certs()
    out: dict[str, Any] = {}
    for scheme, extra in (("ws", []), ("wss", ["--certfile", certfile])):
        c = dataclasses.replace(ctx, bridge_args=[*ctx.bridge_args, *extra])
        r2c = await ros_to_client(c)
        srv = await service(c)
        img = await image(c)
        out[scheme] = {
            "ros_to_client_best_rate_99pct": r2c["best_rate_99pct"],
            "ros_to_client_cpu_us_per_msg": [s["bridge_cpu_us_per_msg"] for s in r2c["steps"]],
            "service_p50_ms": srv["p50_ms"],
            "service_p99_ms": srv["p99_ms"],
            "service_calls_per_s_16_in_flight": srv["calls_per_s"],
            "image_cbor_frames_per_s": img["cbor"]["frames_per_s"],
            "image_cbor_cpu_ms_per_frame": img["cbor"]["bridge_cpu_ms_per_frame"],
            "image_json_frames_per_s": img["json"]["frames_per_s"],
        }
    return out
