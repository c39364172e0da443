"""The value limits of the ROS 2 primitive types, declared once.

The parser (:mod:`msgs.parser`), the typed classes (:mod:`msgs.runtime`) and the bridge's
rclpy conversion (``bridge_server.rclpy_graph.convert``) check values against these. The
module's name starts with ``_`` so that no ROS package (whose names start with a letter)
can take it under ``msgs``.
"""

from __future__ import annotations

__all__ = ["FLOAT32_MAX", "INTEGER_RANGES", "SIZED_INTEGER_RANGES"]

SIZED_INTEGER_RANGES: dict[str, tuple[int, int]] = {
    f"{sign}int{bits}": (0, 2**bits - 1) if sign else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    for bits in (8, 16, 32, 64)
    for sign in ("", "u")
}
"""Inclusive value range of each sized integer type (``int8`` ... ``uint64``), named alike
in ``.msg`` files and in IDL."""

INTEGER_RANGES: dict[str, tuple[int, int]] = {
    "byte": SIZED_INTEGER_RANGES["uint8"],
    "char": SIZED_INTEGER_RANGES["uint8"],
    **SIZED_INTEGER_RANGES,
}
"""Inclusive value range of every integer primitive of ``.msg`` files (``byte`` and
``char`` are octets)."""

FLOAT32_MAX = 3.4028234663852886e38
"""Largest finite float32 magnitude."""
