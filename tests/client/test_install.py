"""The client's import footprint: no rclpy ever, cbor2 only when CBOR is asked for."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

FOOTPRINT = """
import sys
import roslibpy_lite, roslibpy_lite.client, roslibpy_lite.mock, rosbridge_core.protocol
import roslibpy_lite.sync, roslibpy_lite.compat
bad = sorted(m for m in sys.modules if m.split(".")[0] in ("rclpy", "cbor2", "rosidl_runtime_py"))
print(",".join(bad))
"""

WITHOUT_CBOR = """
import asyncio, sys
sys.modules["cbor2"] = None  # as if it were not installed
import roslibpy_lite
from roslibpy_lite import UsageError

async def main() -> None:
    client = roslibpy_lite.Client("ws://127.0.0.1:9")
    try:
        client.subscribe("/x", "std_msgs/msg/String", compression="cbor")
    except UsageError as exc:
        print("refused:", exc)
    client.subscribe("/x", "std_msgs/msg/String")
    async with roslibpy_lite.MockRos() as mock:
        sub = mock.subscribe("/y", "std_msgs/msg/String")
        await mock.advertise("/y", "std_msgs/msg/String").publish({"data": "ok"})
        print("mock:", (await sub.get(1))["data"])
    await client.close()

asyncio.run(main())
"""


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=60, check=True)
    return out.stdout


def test_import_pulls_in_neither_rclpy_nor_cbor2() -> None:
    """Importing the whole client loads no rclpy (never) and no cbor2 (until CBOR is used)."""
    assert _run(FOOTPRINT).strip() == ""


def test_works_without_cbor2_and_says_what_is_missing() -> None:
    """Without cbor2 JSON works and compression='cbor' is refused with a message naming cbor2."""
    out = _run(WITHOUT_CBOR)
    assert "refused:" in out and "cbor2" in out
    assert "mock: ok" in out
