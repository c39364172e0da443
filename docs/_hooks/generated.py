"""mkdocs hook: pages carry the tools' real ``--help`` and the repository's own documents.

- A line ``<!-- help: roslibpy-lite-bridge -->`` (any console script of this
  environment, with arguments) becomes a text block holding that command's
  ``--help`` output, so the option lists in the docs cannot drift from the code (this
  checkout's code: it comes first on the command's ``PYTHONPATH``).
- A line ``<!-- include: SECURITY.md -->`` becomes that file of the repository
  (its title dropped; links to repository files shown as paths, since the
  site does not carry them).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

HELP = re.compile(r"^<!-- help: (.+?) -->$", re.M)
INCLUDE = re.compile(r"^<!-- include: (.+?) -->$", re.M)
REPO_LINK = re.compile(r"\[([^\]]+)\]\((?!https?://|#|mailto:)([^)\s]+)\)")


def _help(root: Path, command: str) -> str:
    program, *args = command.split()
    exe = Path(sys.executable).parent / program
    # This checkout's code, not whatever the environment's console scripts were installed from.
    path = os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, COLUMNS="88", PYTHONPATH=path)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    done = subprocess.run([str(exe), *args, "--help"], capture_output=True, text=True,
                          env=env, timeout=60, check=True)
    return f"```text\n$ {command} --help\n{done.stdout.rstrip()}\n```"


def _include(root: Path, name: str) -> str:
    path = root / name
    if not path.is_file():
        return f"*({name} is not in this checkout.)*"
    text = re.sub(r"\A# .*\n", "", path.read_text())
    return REPO_LINK.sub(lambda m: f"{m.group(1)} (`{m.group(2)}` in the repository)", text)


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    """Replace each help marker with the command's ``--help``, each include with the file."""
    config = kwargs.get("config")
    root = Path(config["docs_dir"]).parent if config else Path.cwd()
    markdown = INCLUDE.sub(lambda m: _include(root, m.group(1)), markdown)
    return HELP.sub(lambda m: _help(root, m.group(1)), markdown)
