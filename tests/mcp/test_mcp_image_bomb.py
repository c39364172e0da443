"""A compressed image declaring more pixels than the bound is refused from its header,
before decompression: a 164 KB palette PNG of 13000x13000 (the red team's bomb took the MCP
server 70 -> 1,850 MiB) costs to_numpy and a real MCP server next to nothing."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zlib
from pathlib import Path
from typing import Any

import psutil
import pytest
from sensor_msgs.msg import CompressedImage

from roslibpy_lite.data import MAX_PIXELS, to_numpy
from roslibpy_lite.exceptions import UsageError
from tests.helpers import ROOT, BridgeProcess, ros_env
from tests.mcp.support import mcp_stdio, text, until_listed

SIDE = 13_000
GROWTH_MIB = 300
"""The most a refused bomb may add to a process's peak memory (decoded it adds ~1,800 MiB)."""


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def png_bomb(width: int, height: int) -> bytes:
    """A valid palette PNG of ``width`` x ``height`` black pixels, compressed row by row (so
    making it costs this process nothing like its decoded size)."""
    packer = zlib.compressobj(9)
    row = b"\x00" * (width + 1)  # the filter byte and one palette index per pixel
    body = b"".join(packer.compress(row) for _ in range(height)) + packer.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"PLTE", b"\x00" * 3)
            + _chunk(b"IDAT", body) + _chunk(b"IEND", b""))


PEAK_SCRIPT = """
import json, resource, sys
from roslibpy_lite.data import to_numpy
data = open(sys.argv[1], "rb").read()
import numpy, PIL.Image  # imported before the baseline
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    shape, error = list(to_numpy({"format": "png", "data": data}).shape), None
except Exception as exc:
    shape, error = None, f"{type(exc).__name__}: {exc}"
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"shape": shape, "error": error, "growth_mib": (after - before) / 1024}))
"""


def test_to_numpy_refuses_the_bomb_from_its_header(tmp_path: Path) -> None:
    """to_numpy on the 164 KB 13000x13000 PNG fails with an error naming the size and the
    bound, and its process's peak memory grows by less than GROWTH_MIB."""
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(png_bomb(SIDE, SIDE))
    assert bomb.stat().st_size < 200_000
    done = subprocess.run([sys.executable, "-c", PEAK_SCRIPT, str(bomb)], cwd=ROOT,
                          env=ros_env(PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                          timeout=120, check=True)
    seen = json.loads(done.stdout)
    print(f"to_numpy on the bomb: peak memory +{seen['growth_mib']:.0f} MiB")
    assert seen["shape"] is None, seen
    assert f"{SIDE}x{SIDE}" in seen["error"] and f"{MAX_PIXELS:,}" in seen["error"], seen
    assert seen["growth_mib"] < GROWTH_MIB, seen


def test_the_bound_is_max_pixels() -> None:
    """A 100x100 PNG decodes under a 10,000-pixel bound and is refused under 9,999."""
    small = {"format": "png", "data": png_bomb(100, 100)}
    assert to_numpy(small, max_pixels=10_000).shape == (100, 100, 3)
    with pytest.raises(UsageError, match=r"100x100 is 10,000 pixels, over the bound of 9,999"):
        to_numpy(small, max_pixels=9_999)


def _peak_mib(pid: int) -> float:
    """A process's peak resident memory (VmHWM) in MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmHWM for {pid}")


def _mcp_child() -> psutil.Process:
    """The ``roslibpy-lite mcp`` process the SDK's stdio client started."""
    (child,) = [p for p in psutil.Process().children(recursive=True)
                if "roslibpy_lite.cli" in p.cmdline() and "mcp" in p.cmdline()]
    return child


async def test_the_mcp_server_refuses_the_bomb_undecoded(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """read_topic on a CompressedImage topic carrying the bomb (through a real bridge) is a
    tool error naming the size and the bound, and the MCP server's peak memory grows by less
    than GROWTH_MIB."""
    publisher = ros_node.create_publisher(CompressedImage, topic, 1)
    bomb = png_bomb(SIDE, SIDE)
    ros_node.create_timer(0.2, lambda: publisher.publish(CompressedImage(format="png",
                                                                         data=bomb)))
    async with mcp_stdio(bridge.url, None, tmp_path) as client:
        await until_listed(client, "list_topics", topic)
        server = _mcp_child()
        before = _peak_mib(server.pid)
        result = await client.call_tool("read_topic", {"topic": topic, "timeout": 30})
        growth = _peak_mib(server.pid) - before
    print(f"the MCP server's peak memory on the bomb: +{growth:.0f} MiB (from {before:.0f})")
    assert result.is_error, text(result)
    assert f"{SIDE}x{SIDE}" in text(result) and f"{MAX_PIXELS:,}" in text(result)
    assert growth < GROWTH_MIB, growth
