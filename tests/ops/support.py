"""Helpers for the operations tests: plain HTTP against a bridge, parsed metrics."""

from __future__ import annotations

import asyncio
import json
import urllib.error
import urllib.request
from typing import Any

from prometheus_client.parser import text_string_to_metric_families


def http_get(url: str, timeout: float = 10.0) -> tuple[int, dict[str, str], bytes]:
    """GET ``url``: status, headers (lower-case names), body; HTTP errors are returned too."""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            return r.status, {k.lower(): v for k, v in r.headers.items()}, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, {k.lower(): v for k, v in exc.headers.items()}, exc.read()


async def aget(url: str) -> tuple[int, dict[str, str], bytes]:
    """:func:`http_get` off the event loop."""
    return await asyncio.to_thread(http_get, url)


async def status(port: int) -> dict[str, Any]:
    """The bridge's ``/status.json``."""
    code, _, body = await aget(f"http://127.0.0.1:{port}/status.json")
    assert code == 200, body
    data: dict[str, Any] = json.loads(body)
    return data


async def scrape(port: int) -> dict[str, list[tuple[dict[str, str], float]]]:
    """``/metrics`` parsed: sample name -> [(labels, value)]."""
    code, headers, body = await aget(f"http://127.0.0.1:{port}/metrics")
    assert code == 200, body
    assert headers["content-type"].startswith("text/plain")
    out: dict[str, list[tuple[dict[str, str], float]]] = {}
    for family in text_string_to_metric_families(body.decode()):
        for sample in family.samples:
            out.setdefault(sample.name, []).append((dict(sample.labels), sample.value))
    return out


def value(samples: dict[str, list[tuple[dict[str, str], float]]], name: str,
          **labels: str) -> float:
    """The value of the one sample ``name`` with these labels (0 if absent)."""
    for got, v in samples.get(name, []):
        if all(got.get(k) == want for k, want in labels.items()):
            return v
    return 0.0
