"""The blocking client in a real Jupyter kernel (whose asyncio loop already runs), through the bridge."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import nbformat
import pytest
from jupyter_client.kernelspec import KernelSpecManager
from jupyter_client.manager import AsyncKernelManager
from nbclient import NotebookClient

from tests.helpers import ROOT, BridgeProcess

KERNEL = "roslibpy-lite-test"

CELLS = [
    # The parameters: where the bridge is, and a name of our own.
    "import os\nURL = os.environ['ROSLIBPY_LITE_NOTEBOOK_URL']\n"
    "NAME = os.environ['ROSLIBPY_LITE_NOTEBOOK_NAME']",
    # The kernel runs cells inside its own asyncio loop: what breaks asyncio.run().
    "import asyncio, sys\nprint('python:', sys.executable)\n"
    "print('loop running:', asyncio.get_running_loop().is_running())",
    # A served service, called through the bridge and ROS, without await.
    "from roslibpy_lite import sync\n"
    "ros = sync.connect(URL)\n"
    "server = ros.advertise_service(NAME, 'mult_msgs/srv/MultFloats',\n"
    "                               lambda req: {'result': req['x'] * req['y']})\n"
    "print('result:', ros.call_service(NAME, 'mult_msgs/srv/MultFloats', {'x': 6.0, 'y': 7.0},"
    " timeout=30)['result'])",
    # Messages round the bridge and ROS (published until heard: discovery has no event).
    "from roslibpy_lite import RosTimeoutError\n"
    "sub = ros.subscribe(NAME + '_chat', 'std_msgs/msg/String')\n"
    "pub = ros.advertise(NAME + '_chat', 'std_msgs/msg/String')\n"
    "for _ in range(60):\n"
    "    pub.publish({'data': 'hello from a notebook'})\n"
    "    try:\n"
    "        print('heard:', sub.get(timeout=0.25)['data'])\n"
    "        break\n"
    "    except RosTimeoutError:\n"
    "        pass",
    # Closing leaves no thread of the client behind.
    "import threading\nros.close()\n"
    "print('state:', ros.state.value)\n"
    "print('threads left:', sum(t.name.startswith('roslibpy_lite.sync') for t in "
    "threading.enumerate()))",
]


def _kernel_manager(tmp_path: Path) -> AsyncKernelManager:
    """A kernel of THIS interpreter (the venv's), whatever kernels the machine has installed."""
    spec_dir = tmp_path / "kernels" / KERNEL
    spec_dir.mkdir(parents=True)
    (spec_dir / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "roslibpy-lite tests",
        "language": "python",
    }))
    specs = KernelSpecManager(kernel_dirs=[str(tmp_path / "kernels")])
    return AsyncKernelManager(kernel_name=KERNEL, kernel_spec_manager=specs)


def _stdout(cell: Any) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.get("name") == "stdout")


def test_blocking_client_in_a_jupyter_kernel(
    bridge: BridgeProcess, topic: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A notebook connects, serves and calls a service, hears a message and closes cleanly."""
    monkeypatch.setenv("ROSLIBPY_LITE_NOTEBOOK_URL", bridge.url)
    monkeypatch.setenv("ROSLIBPY_LITE_NOTEBOOK_NAME", topic)
    monkeypatch.setenv("JUPYTER_RUNTIME_DIR", str(tmp_path / "runtime"))  # nothing in $HOME
    monkeypatch.setenv("IPYTHONDIR", str(tmp_path / "ipython"))
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])
    km = _kernel_manager(tmp_path)
    client = NotebookClient(nb, km=km, timeout=90, resources={"metadata": {"path": str(ROOT)}})
    client.execute(cleanup_kc=True)  # shut the kernel and its channels down (km is ours)
    outputs = [_stdout(cell) for cell in nb.cells]
    assert outputs[1:] == [
        f"python: {sys.executable}\nloop running: True\n",
        "result: 42.0\n",
        "heard: hello from a notebook\n",
        "state: closed\nthreads left: 0\n",
    ]
