"""py-spy on a bridge for a while, reduced to its top functions (``python -m bench --profile``:
the ``ros_to_client``, ``image``, ``service`` and ``client_service`` scenarios add the bridge's
to their results, ``record`` the recorder's)."""

from __future__ import annotations

import asyncio
import os
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any


def py_spy() -> str | None:
    """py-spy's path: on the PATH, or beside this Python (the venv's, when the benchmark runs
    as ``.venv/bin/python -m bench`` with the venv not on the PATH); None if not installed."""
    beside = Path(sys.executable).with_name("py-spy")
    return shutil.which("py-spy") or (str(beside) if beside.exists() else None)


class Profiler:
    """py-spy on the bridge for a while, reduced to the top functions."""

    def __init__(self, pid: int, seconds: float) -> None:
        self.pid = pid
        self.seconds = seconds
        self.out = Path(tempfile.mkdtemp(prefix="bench-pyspy-")) / "stacks.txt"
        self.proc: asyncio.subprocess.Process | None = None

    @classmethod
    async def maybe(cls, wanted: bool, pid: int, seconds: float) -> Profiler | None:
        """A started profiler of ``pid`` for ``seconds`` when ``wanted`` (``--profile``)."""
        if not wanted:
            return None
        prof = cls(pid, seconds)
        await prof.start()
        return prof

    async def start(self) -> None:
        """Start sampling (nothing happens if py-spy is not installed)."""
        exe = py_spy()
        if exe is None:
            return
        self.proc = await asyncio.create_subprocess_exec(
            exe, "record", "--pid", str(self.pid), "--duration", str(max(1, round(self.seconds))),
            "--rate", "250", "--format", "raw", "--output", str(self.out), "--nonblocking",
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
        )

    async def result(self, top: int = 30) -> dict[str, Any]:
        """Wait for py-spy and summarise: top functions by self and by inclusive samples."""
        if self.proc is None:
            return {"error": "py-spy not installed"}
        try:
            await asyncio.wait_for(self.proc.wait(), self.seconds + 20)
        except TimeoutError:
            self.proc.kill()
            await self.proc.wait()
        if not self.out.exists():
            return {"error": "py-spy wrote nothing (permissions?)"}
        own: Counter[str] = Counter()
        incl: Counter[str] = Counter()
        total = 0
        for line in self.out.read_text().splitlines():
            stack, _, n = line.rpartition(" ")
            if not stack or not n.isdigit():
                continue
            count = int(n)
            total += count
            frames = [_short(f) for f in stack.split(";")]
            own[frames[-1]] += count
            for f in set(frames):
                incl[f] += count
        shutil.rmtree(self.out.parent, ignore_errors=True)

        def pct(c: Counter[str]) -> list[tuple[str, float]]:
            return [(f, round(100.0 * n / total, 1)) for f, n in c.most_common(top)] if total else []

        return {"samples": total, "self_pct": pct(own), "inclusive_pct": pct(incl)}


def _short(frame: str) -> str:
    """``func (path/to/file.py:123)`` -> ``func (file.py:123)``."""
    name, sep, where = frame.partition(" (")
    if not sep:
        return frame
    return f"{name} ({os.path.basename(where.rstrip(')'))})"
