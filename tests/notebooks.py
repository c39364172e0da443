"""Real Jupyter kernels for the tests: a kernel of THIS interpreter, its environment, and
reading what a cell wrote (tests/sync/test_notebook.py, tests/docs/test_notebooks_guide.py)."""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from jupyter_client.kernelspec import KernelSpecManager
from jupyter_client.manager import AsyncKernelManager, KernelManager

from tests.helpers import ROOT

KERNEL = "roslibpy-lite-test"


def kernel_manager(tmp_path: Path, cls: type[Any] = AsyncKernelManager) -> Any:
    """A kernel of THIS interpreter (the venv's), whatever kernels the machine has installed."""
    spec_dir = tmp_path / "kernels" / KERNEL
    spec_dir.mkdir(parents=True)
    (spec_dir / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "roslibpy-lite tests",
        "language": "python",
    }))
    specs = KernelSpecManager(kernel_dirs=[str(tmp_path / "kernels")])
    return cls(kernel_name=KERNEL, kernel_spec_manager=specs)


@contextlib.contextmanager
def running_kernel(tmp_path: Path) -> Iterator[tuple[Any, Any]]:
    """A started kernel (run in the repository) and a ready client of it, shut down after."""
    km = kernel_manager(tmp_path, KernelManager)
    km.start_kernel(cwd=str(ROOT))
    kc = km.client()
    kc.start_channels()
    try:
        kc.wait_for_ready(timeout=60)
        yield km, kc
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)


def kernel_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, **names: str) -> None:
    """The kernel's environment: ``ROSLIBPY_LITE_NOTEBOOK_<KEY>`` for each name, and no
    files in $HOME."""
    for key, value in names.items():
        monkeypatch.setenv(f"ROSLIBPY_LITE_NOTEBOOK_{key.upper()}", value)
    monkeypatch.setenv("JUPYTER_RUNTIME_DIR", str(tmp_path / "runtime"))
    monkeypatch.setenv("IPYTHONDIR", str(tmp_path / "ipython"))


def stdout_of(cell: Any) -> str:
    """What an executed notebook cell printed."""
    return "".join(o.get("text", "") for o in cell.outputs if o.get("name") == "stdout")


def run_cell(kc: Any, code: str, timeout: float = 60) -> str:
    """Execute ``code`` in the kernel; its stdout (fails on an error in the cell)."""
    out: list[str] = []

    def hook(msg: dict[str, Any]) -> None:
        if msg["msg_type"] == "stream":
            out.append(msg["content"]["text"])

    reply = kc.execute_interactive(code, timeout=timeout, output_hook=hook)
    assert reply["content"]["status"] == "ok", reply["content"]
    return "".join(out)


def run_collecting_all(kc: Any, code: str, timeout: float = 60) -> list[dict[str, Any]]:
    """Execute ``code``; every output message (stream, display) the kernel sent meanwhile,
    whatever request it is attributed to (fails on an error in the cell)."""
    msg_id = kc.execute(code)
    seen: list[dict[str, Any]] = []
    while True:
        msg = kc.get_iopub_msg(timeout=timeout)
        parent = msg["parent_header"].get("msg_id", "")
        if msg["msg_type"] in ("stream", "display_data", "update_display_data"):
            seen.append(msg)
        elif msg["msg_type"] == "error" and parent == msg_id:
            raise AssertionError("\n".join(msg["content"]["traceback"]))
        elif (msg["msg_type"] == "status" and parent == msg_id
              and msg["content"]["execution_state"] == "idle"):
            return seen


def run_collecting(kc: Any, code: str, timeout: float = 60) -> list[tuple[str, str]]:
    """Execute ``code``; every stream output the kernel sent meanwhile, as ``(msg_id of the
    request it is attributed to, text)``, whatever request that is (fails on an error)."""
    return [(m["parent_header"].get("msg_id", ""), m["content"]["text"])
            for m in run_collecting_all(kc, code, timeout) if m["msg_type"] == "stream"]


def executed(kc: Any, code: str, timeout: float = 60) -> str:
    """Execute ``code`` (fails on an error in the cell); the request's msg_id."""
    reply = kc.execute_interactive(code, timeout=timeout, output_hook=lambda msg: None)
    assert reply["content"]["status"] == "ok", reply["content"]
    return str(reply["parent_header"]["msg_id"])
