"""Child processes for the relay tests: output kept, awaited by pattern, shown on failure."""

from __future__ import annotations

import re
import subprocess
import threading
import time
import urllib.error
import urllib.request

from tests.helpers import ROOT

__all__ = ["Proc", "until_robot_served"]


class Proc:
    """A child process whose output is kept (and shown when a test fails)."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self.lines: list[str] = []
        self.seen = threading.Condition()
        self.proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self.seen:
                self.lines.append(line.rstrip())
                self.seen.notify_all()

    def wait_for(self, pattern: re.Pattern[str], timeout: float = 30.0) -> re.Match[str]:
        """The first output line matching ``pattern`` (waiting for it)."""
        def found() -> re.Match[str] | None:
            return next((m for line in self.lines if (m := pattern.search(line))), None)

        with self.seen:
            if not self.seen.wait_for(lambda: found() is not None or self.proc.poll() is not None,
                                      timeout):
                raise AssertionError(f"no line like {pattern.pattern!r}:\n" + "\n".join(self.lines))
        match = found()
        assert match is not None, "exited:\n" + "\n".join(self.lines)
        return match

    def stop(self) -> None:
        """SIGTERM, then SIGKILL."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


def until_robot_served(port: int, robot: str, timeout: float = 30.0) -> None:
    """Wait until the relay on ``port`` has ``robot`` (its /ROBOT/readyz answers 200: a
    relay in another process gives no event for it)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/{robot}/readyz", timeout=5):
                return
        except (OSError, urllib.error.HTTPError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
