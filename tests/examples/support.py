"""Child processes for the example and demo tests: output kept line by line, waited on by pattern."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from tests.helpers import ROOT, ros_env


class Program:
    """A child process whose stdout and stderr lines are collected as they arrive.

    ``group=True`` starts it in a new process group, so :meth:`interrupt` can
    signal the whole group the way Ctrl+C in a terminal does.
    """

    def __init__(
        self,
        cmd: Sequence[str],
        *,
        env: dict[str, str] | None = None,
        cwd: Path = ROOT,
        group: bool = False,
    ) -> None:
        self.cmd = list(cmd)
        self.group = group
        self.out: list[str] = []
        self.err: list[str] = []
        self._cond = threading.Condition()
        self.proc = subprocess.Popen(
            self.cmd, cwd=cwd, env=env if env is not None else ros_env(),
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, bufsize=1, start_new_session=group,
        )
        assert self.proc.stdout is not None and self.proc.stderr is not None
        self._threads = [
            threading.Thread(target=self._pump, args=(self.proc.stdout, self.out), daemon=True),
            threading.Thread(target=self._pump, args=(self.proc.stderr, self.err), daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _pump(self, stream: object, lines: list[str]) -> None:
        for line in stream:  # type: ignore[attr-defined]
            with self._cond:
                lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        stream.close()  # type: ignore[attr-defined]
        with self._cond:
            self._cond.notify_all()

    def wait_for(
        self, pattern: str, timeout: float = 20.0, *, stream: str = "out", start: int = 0
    ) -> re.Match[str]:
        """Wait until a line of ``stream`` ("out" or "err") from ``start`` on matches ``pattern``."""
        rx = re.compile(pattern)
        lines = self.out if stream == "out" else self.err
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for line in lines[start:]:
                    m = rx.search(line)
                    if m:
                        return m
                if self.proc.poll() is not None and all(not t.is_alive() for t in self._threads):
                    raise AssertionError(
                        f"{self.cmd[:3]} exited ({self.proc.returncode}) before /{pattern}/:\n"
                        + self.dump()
                    )
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no line matching /{pattern}/ in {timeout} s:\n"
                                         + self.dump())
                self._cond.wait(min(left, 0.5))

    def dump(self) -> str:
        """The last lines of both streams, for failure messages."""
        with self._cond:
            return ("--- stdout\n" + "\n".join(self.out[-60:])
                    + "\n--- stderr\n" + "\n".join(self.err[-60:]))

    def interrupt(self, timeout: float = 20.0) -> int:
        """Send SIGINT (to the group if ``group``) and wait for exit; returns the exit status."""
        if self.proc.poll() is None:
            if self.group:
                os.killpg(self.proc.pid, signal.SIGINT)
            else:
                self.proc.send_signal(signal.SIGINT)
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError("did not exit after SIGINT:\n" + self.dump()) from None
        for t in self._threads:
            t.join(10)
        return code

    def kill(self) -> None:
        """Kill it (and its group) at once; used for clean-up after a failure."""
        if self.group:  # children may outlive the leader
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
        elif self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for t in self._threads:
            t.join(10)
