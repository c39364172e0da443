"""mkdocs hook: pages carry the real ``--help`` of the tools, generated at build time.

A line ``<!-- help: roslibpy-lite-bridge -->`` (any console script of this
environment, with arguments) becomes a text block holding that command's
``--help`` output, so the option lists in the docs cannot drift from the code.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

HELP = re.compile(r"^<!-- help: (.+?) -->$", re.M)


def _help(command: str) -> str:
    program, *args = command.split()
    exe = Path(sys.executable).parent / program
    env = dict(os.environ, COLUMNS="88")
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    done = subprocess.run([str(exe), *args, "--help"], capture_output=True, text=True,
                          env=env, timeout=60, check=True)
    return f"```text\n$ {command} --help\n{done.stdout.rstrip()}\n```"


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    """Replace each help marker with the command's ``--help`` output."""
    return HELP.sub(lambda m: _help(m.group(1)), markdown)
