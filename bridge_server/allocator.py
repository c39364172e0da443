"""glibc's allocator settings for a server that handles large messages (the bridge and the
relay set them at start-up).

By default glibc serves an allocation above 128 KiB with a fresh ``mmap`` and, each time one
is freed, raises that threshold to the freed size (up to 32 MiB): after the first camera
frame or large fragment, buffers of that size come from the heap, and a heap keeps what it
once held. Thirty 15.9 MB frames refused one after another then left the bridge 150 to 380
MiB larger (the more, the busier the machine), though it held only 64 MiB of them.
:func:`tune_allocator` fixes the threshold instead: buffers up to ``mmap_threshold`` (a
1080p frame, a 4 MiB point cloud) are reused from the heap, as before, without page faults
per message; larger ones are mapped and given back to the system when freed.
"""

from __future__ import annotations

import sys
from typing import Final

__all__ = ["MMAP_THRESHOLD", "tune_allocator"]

MMAP_THRESHOLD: Final = 8 * 1024 * 1024
"""Buffers up to this size stay on the heap; larger ones are mapped and returned on free."""

_M_TRIM_THRESHOLD: Final = -1
_M_MMAP_THRESHOLD: Final = -3


def tune_allocator(mmap_threshold: int = MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``mmap_threshold`` and its heap trim threshold at twice
    that (see the module docstring). Returns False where it cannot apply (not glibc)."""
    import ctypes
    import ctypes.util

    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok: bool = mallopt(_M_MMAP_THRESHOLD, mmap_threshold) == 1
    trim_ok: bool = mallopt(_M_TRIM_THRESHOLD, 2 * mmap_threshold) == 1
    return ok and trim_ok
