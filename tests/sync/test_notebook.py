"""The blocking client in a real Jupyter kernel (whose asyncio loop already runs), through the bridge.

The kernel is this interpreter (a kernelspec written for the test), so it sees the venv.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import nbformat
import pytest
from jupyter_client.kernelspec import KernelSpecManager
from jupyter_client.manager import AsyncKernelManager, KernelManager
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


def _kernel_manager(tmp_path: Path, cls: type[Any] = AsyncKernelManager) -> Any:
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


def _stdout(cell: Any) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.get("name") == "stdout")


@pytest.fixture
def kernel_env(bridge: BridgeProcess, topic: str, tmp_path: Path,
               monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel's environment: the bridge's URL, a name of the test's own, no files in $HOME."""
    monkeypatch.setenv("ROSLIBPY_LITE_NOTEBOOK_URL", bridge.url)
    monkeypatch.setenv("ROSLIBPY_LITE_NOTEBOOK_NAME", topic)
    monkeypatch.setenv("JUPYTER_RUNTIME_DIR", str(tmp_path / "runtime"))
    monkeypatch.setenv("IPYTHONDIR", str(tmp_path / "ipython"))


@pytest.mark.usefixtures("kernel_env")
def test_blocking_client_in_a_jupyter_kernel(tmp_path: Path) -> None:
    """A notebook connects, serves and calls a service, hears a message and closes cleanly."""
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])  # type: ignore[no-untyped-call]
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


def _run(kc: Any, code: str) -> str:
    """Execute ``code`` in the kernel; its stdout (fails on an error in the cell)."""
    out: list[str] = []

    def hook(msg: dict[str, Any]) -> None:
        if msg["msg_type"] == "stream":
            out.append(msg["content"]["text"])

    reply = kc.execute_interactive(code, timeout=60, output_hook=hook)
    assert reply["content"]["status"] == "ok", reply["content"]
    return "".join(out)


@pytest.mark.usefixtures("kernel_env")
def test_interrupting_a_blocking_call_in_a_kernel(tmp_path: Path) -> None:
    """Interrupting the kernel (Jupyter's stop button) ends a waiting get(); the client still works."""
    km = _kernel_manager(tmp_path, KernelManager)
    km.start_kernel(cwd=str(ROOT))
    kc = km.client()
    kc.start_channels()
    try:
        kc.wait_for_ready(timeout=60)
        _run(kc, CELLS[0] + "\nfrom roslibpy_lite import sync\nros = sync.connect(URL)\n"
                 "sub = ros.subscribe(NAME, 'std_msgs/msg/Int32')")
        # no timeout: for ever. stop_on_error=False: the kernel would otherwise abort the
        # requests that reach it just after this cell's error reply (the next _run: a race)
        msg_id = kc.execute("print('waiting', flush=True)\nsub.get()", stop_on_error=False)
        while True:  # the cell is running once its first line printed
            msg = kc.get_iopub_msg(timeout=30)
            if msg["parent_header"].get("msg_id") == msg_id and msg["msg_type"] == "stream":
                break
        km.interrupt_kernel()
        reply = kc.get_shell_msg(timeout=30)
        assert reply["parent_header"]["msg_id"] == msg_id
        assert (reply["content"]["status"], reply["content"].get("ename")) == (
            "error", "KeyboardInterrupt")
        # The interrupted get() was cancelled on the loop thread: a new one may wait again.
        assert _run(kc, "try:\n    sub.get(timeout=0.2)\nexcept Exception as exc:\n"
                        "    print(type(exc).__name__)\n"
                        "print(ros.state.value, ros.call_service('/rosapi/topics', "
                        "'rosapi_msgs/srv/Topics', timeout=30)['topics'].__class__.__name__)\n"
                        "ros.close()") == "RosTimeoutError\nconnected list\n"
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)
