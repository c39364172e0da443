"""The blocking client in a real Jupyter kernel (whose asyncio loop already runs), through the bridge.

The kernel is this interpreter (a kernelspec written for the test), so it sees the venv.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import nbformat
import pytest
from nbclient import NotebookClient

from tests import notebooks
from tests.helpers import ROOT, BridgeProcess, wait_until

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


@pytest.fixture
def kernel_env(bridge: BridgeProcess, topic: str, tmp_path: Path,
               monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel's environment: the bridge's URL, a name of the test's own, no files in $HOME."""
    notebooks.kernel_env(monkeypatch, tmp_path, url=bridge.url, name=topic)


@pytest.mark.usefixtures("kernel_env")
def test_blocking_client_in_a_jupyter_kernel(tmp_path: Path) -> None:
    """A notebook connects, serves and calls a service, hears a message and closes cleanly."""
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in CELLS])  # type: ignore[no-untyped-call]
    km = notebooks.kernel_manager(tmp_path)
    client = NotebookClient(nb, km=km, timeout=90, resources={"metadata": {"path": str(ROOT)}})
    client.execute(cleanup_kc=True)  # shut the kernel and its channels down (km is ours)
    outputs = [notebooks.stdout_of(cell) for cell in nb.cells]
    assert outputs[1:] == [
        f"python: {sys.executable}\nloop running: True\n",
        "result: 42.0\n",
        "heard: hello from a notebook\n",
        "state: closed\nthreads left: 0\n",
    ]


@pytest.mark.usefixtures("kernel_env")
def test_interrupting_a_blocking_call_in_a_kernel(tmp_path: Path) -> None:
    """Interrupting the kernel (Jupyter's stop button) ends a waiting get(); the client still works."""
    with notebooks.running_kernel(tmp_path) as (km, kc):
        notebooks.run_cell(kc, CELLS[0] + "\nfrom roslibpy_lite import sync\nros = sync.connect(URL)\n"
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
        assert notebooks.run_cell(kc, "try:\n    sub.get(timeout=0.2)\nexcept Exception as exc:\n"
                        "    print(type(exc).__name__)\n"
                        "print(ros.state.value, ros.call_service('/rosapi/topics', "
                        "'rosapi_msgs/srv/Topics', timeout=30)['topics'].__class__.__name__)\n"
                        "ros.close()") == "RosTimeoutError\nconnected list\n"


@pytest.mark.usefixtures("kernel_env")
def test_callback_output_goes_to_the_cell_that_subscribed(tmp_path: Path) -> None:
    """A callback's print, made while a later cell runs, is sent as output of the cell that
    subscribed: on the blocking client (loop thread) and the asyncio client (its task)."""
    with notebooks.running_kernel(tmp_path) as (_, kc):
        notebooks.executed(kc, CELLS[0] + "\nimport asyncio, threading\nimport roslibpy_lite\n"
                           "from roslibpy_lite import sync\nros = sync.connect(URL)\n"
                           "aros = await roslibpy_lite.connect(URL)\n"
                           "pub = ros.advertise(NAME, 'std_msgs/msg/Int32')\n"
                           "blocking_heard, async_heard = threading.Event(), asyncio.Event()")
        subscribed = notebooks.executed(
            kc, "def on_blocking(msg):\n    print('blocking callback', msg['data'])\n"
                "    blocking_heard.set()\n"
                "def on_async(msg):\n    print('async callback', msg['data'])\n"
                "    async_heard.set()\n"
                "ros.subscribe(NAME, 'std_msgs/msg/Int32', on_blocking)\n"
                "await aros.subscribe(NAME, 'std_msgs/msg/Int32', on_async)")
        # Published until both heard (ROS discovery has no event), from a later cell.
        seen = notebooks.run_collecting(
            kc, "for i in range(300):\n    pub.publish({'data': i})\n"
                "    await asyncio.sleep(0.05)\n"
                "    if blocking_heard.is_set() and async_heard.is_set():\n        break\n"
                "print('both heard:', blocking_heard.is_set() and async_heard.is_set())")
        # The wrapper reads as the function (a re-run cell's subscribe can recognise it).
        same = notebooks.run_cell(
            kc, "from roslibpy_lite.jupyter import in_cell\nw = in_cell(on_blocking)\n"
                "print(w is not on_blocking, w == on_blocking, hash(w) == hash(on_blocking),\n"
                "      w.__code__ is on_blocking.__code__, w.__qualname__, in_cell(w) is w)\n"
                "ros.close()\nawait aros.close()")
    callbacks = [(parent, text) for parent, text in seen if "callback" in text]
    assert any("both heard: True" in text for _, text in seen), seen
    assert {kind for _, text in callbacks for kind in ("blocking", "async") if kind in text} == {
        "blocking", "async"}
    assert {parent for parent, _ in callbacks} == {subscribed}, seen
    assert same == "True True True True on_blocking True\n"


def test_state_and_reconnect_log_in_the_notebook(
    make_bridge: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """jupyter.show_log() and show_state(ros): when the bridge goes and comes back, the log
    lines and the rewritten state line are output of the cell that asked for them."""
    private = make_bridge()
    notebooks.kernel_env(monkeypatch, tmp_path, url=private.url, name="/unused")
    with notebooks.running_kernel(tmp_path) as (_, kc):
        notebooks.executed(kc, CELLS[0] + "\nfrom roslibpy_lite import jupyter, sync\n"
                           "ros = sync.connect(URL)\nchanges = ros.state_changes()")
        shown = notebooks.executed(kc, "jupyter.show_log()\njupyter.show_state(ros)")
        private.stop()
        while_down = notebooks.run_collecting_all(
            kc, "print(changes.next(timeout=30).value)")
        private.start()
        back = notebooks.run_collecting_all(kc, "print(changes.next(timeout=60).value)\n"
                                                "ros.close()")
    seen = while_down + back
    printed = [m["content"]["text"] for m in seen if m["msg_type"] == "stream"
               and m["content"]["name"] == "stdout"]
    assert printed == ["reconnecting\n", "connected\n"]
    logged = [m for m in seen if m["msg_type"] == "stream" and m["content"]["name"] == "stderr"]
    assert any("lost; reconnecting" in m["content"]["text"] for m in logged), seen
    assert {m["parent_header"]["msg_id"] for m in logged} == {shown}
    updates = [m["content"]["data"]["text/plain"] for m in seen
               if m["msg_type"] == "update_display_data"]
    assert [u.split(" since ")[0] for u in updates] == [
        f"{private.url}: reconnecting", f"{private.url}: connected", f"{private.url}: closed"]
    assert all(u.endswith(" (1 reconnect)") for u in updates), updates


def test_an_asyncio_connect_cell_run_again_replaces_its_client(
        make_bridge: Any, topic: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ros = await roslibpy_lite.connect(URL)`` with a subscribe, run three times in a real
    kernel: each re-run warns and closes the earlier client, so the bridge keeps one."""
    import asyncio

    from tests.ops.support import scrape, value

    bridge = make_bridge()
    notebooks.kernel_env(monkeypatch, tmp_path, url=bridge.url, name=topic)
    cell = ("import os, roslibpy_lite\n"
            "ros = await roslibpy_lite.connect(os.environ['ROSLIBPY_LITE_NOTEBOOK_URL'])\n"
            "sub = ros.subscribe(os.environ['ROSLIBPY_LITE_NOTEBOOK_NAME'], 'std_msgs/msg/Int32')\n"
            "print('subscriptions:', len(ros.subscriptions()))")
    with notebooks.running_kernel(tmp_path) as (_, kc):
        outputs = [notebooks.run_collecting_all(kc, cell) for _ in range(3)]
        texts = ["".join(m["content"].get("text", "") for m in out) for out in outputs]
        assert "ReplacedClientWarning" not in texts[0]
        for text in texts[1:]:
            assert "ReplacedClientWarning" in text and bridge.url in text, text
            assert "closed with its 1 subscription(s)" in text, text
        wait_until(lambda: value(asyncio.run(scrape(bridge.port)),
                                 "roslibpy_bridge_clients") == 1, 10, "one client on the bridge")
        notebooks.run_cell(kc, "await ros.close()")


def _streams_by_cell(seen: list[dict[str, Any]]) -> dict[str, str]:
    """The text of every stream message, joined per request (cell run) it is attributed to."""
    out: dict[str, str] = {}
    for m in seen:
        if m["msg_type"] == "stream":
            parent = m["parent_header"].get("msg_id", "")
            out[parent] = out.get(parent, "") + m["content"]["text"]
    return out


@pytest.mark.usefixtures("kernel_env")
def test_a_raising_callback_is_reported_once_under_its_cell(tmp_path: Path) -> None:
    """Callbacks raising at 50 Hz (a blocking call in the blocking client's, 1/0 in the asyncio
    client's) leave under the cell that subscribed one traceback and one count line each,
    and nothing under the connect cell."""
    with notebooks.running_kernel(tmp_path) as (_, kc):
        connected = notebooks.executed(
            kc, CELLS[0] + "\nimport asyncio\nimport roslibpy_lite\nfrom roslibpy_lite import sync\n"
                "ros = sync.connect(URL)\naros = await roslibpy_lite.connect(URL)\n"
                "pub = ros.advertise(NAME, 'std_msgs/msg/Int32')")
        subscribed = notebooks.executed(
            kc, "def on_blocking(msg):\n    ros.graph.topics()  # blocking: raises UsageError\n"
                "def on_async(msg):\n    1 / 0\n"
                "bsub = ros.subscribe(NAME, 'std_msgs/msg/Int32', on_blocking)\n"
                "asub = await aros.subscribe(NAME, 'std_msgs/msg/Int32', on_async)")
        # Published at 50 Hz until each callback failed 100 times (discovery has no event).
        seen = notebooks.run_collecting_all(
            kc, "for i in range(1500):\n    pub.publish({'data': i})\n"
                "    await asyncio.sleep(0.02)\n"
                "    if min(bsub.handle.callback_errors, asub.callback_errors) >= 100:\n"
                "        break\n"
                "bsub.close()\nawait asub.close()\n"
                "print('failures:', bsub.handle.callback_errors >= 100, asub.callback_errors >= 100)"
                "\nros.close()\nawait aros.close()", timeout=90)
    text = _streams_by_cell(seen)
    assert connected not in text, text.get(connected, "")[:2000]
    under = text[subscribed]
    assert under.count("Traceback (most recent call last)") == 2, under[:3000]
    assert under.count("UsageError") >= 1 and under.count("ZeroDivisionError") >= 1, under
    counts = [line for line in under.splitlines() if " more times in the last " in line]
    assert len(counts) == 2, under
    assert {c.split()[1] for c in counts} == {"on_blocking", "on_async"}, counts
    assert len(under) < 10_000
    assert "failures: True True\n" in text.values()


@pytest.mark.usefixtures("kernel_env")
def test_a_subscribe_cell_run_again_keeps_one_subscription(tmp_path: Path) -> None:
    """A ``msgs = []; ros.subscribe(topic, type, msgs.append)`` cell (and one without a
    callback), run 5 times on either client, leaves one live subscription per line: the
    earlier runs' lists get nothing, and each re-run says what it closed."""
    cell = ("msgs, amsgs = [], []\nruns.append(msgs)\n"
            "sub = ros.subscribe(NAME, 'std_msgs/msg/Int32', msgs.append)\n"
            "asub = await aros.subscribe(NAME, 'std_msgs/msg/Int32', amsgs.append)\n"
            "plain = ros.subscribe(NAME + '_plain', 'std_msgs/msg/Int32')\n"
            "print('open:', len(ros.subscriptions()), len(aros.subscriptions()))")
    with notebooks.running_kernel(tmp_path) as (_, kc):
        notebooks.run_cell(kc, CELLS[0] + "\nimport asyncio\nimport roslibpy_lite\n"
                           "from roslibpy_lite import sync\nros = sync.connect(URL)\n"
                           "aros = await roslibpy_lite.connect(URL)\nruns = []\n"
                           "pub = ros.advertise(NAME, 'std_msgs/msg/Int32')")
        outputs = [notebooks.run_collecting_all(kc, cell) for _ in range(5)]
        heard = notebooks.run_cell(
            kc, "for i in range(300):\n    pub.publish({'data': i})\n"
                "    await asyncio.sleep(0.05)\n    if msgs and amsgs:\n        break\n"
                "print([len(m) > 0 for m in runs])\nros.close()\nawait aros.close()")
    texts = ["".join(m["content"].get("text", "") for m in out) for out in outputs]
    assert all("open: 2 1\n" in text for text in texts), texts
    assert "ReplacedSubscriptionWarning" not in texts[0]
    for text in texts[1:]:
        assert text.count("ReplacedSubscriptionWarning") == 3, text
    assert heard == "[False, False, False, False, True]\n"


@pytest.mark.usefixtures("kernel_env")
def test_numpy_scalars_publish_and_call(tmp_path: Path, topic: str) -> None:
    """np.float32, np.int64, np.bool_ and a 0-d array publish and call through the bridge as
    Python numbers do; a value out of range is refused naming numpy's type."""
    with notebooks.running_kernel(tmp_path) as (_, kc):
        out = notebooks.run_cell(
            kc, CELLS[0] + "\nimport numpy as np\nfrom roslibpy_lite import sync, RosTimeoutError\n"
                "from roslibpy_lite import InvalidMessageError\nros = sync.connect(URL)\n"
                "server = ros.advertise_service(NAME, 'mult_msgs/srv/MultFloats',\n"
                "    lambda req: {'result': req['x'] * req['y']})\n"
                "print('call:', ros.call_service(NAME, 'mult_msgs/srv/MultFloats',\n"
                "    {'x': np.float32(1.5), 'y': np.int64(4)}, timeout=30)['result'])\n"
                "sub = ros.subscribe(NAME + '_v', 'geometry_msgs/msg/Vector3')\n"
                "flag = ros.subscribe(NAME + '_b', 'std_msgs/msg/Bool')\n"
                "pub = ros.advertise(NAME + '_v', 'geometry_msgs/msg/Vector3')\n"
                "bpub = ros.advertise(NAME + '_b', 'std_msgs/msg/Bool')\n"
                "for _ in range(60):\n"
                "    pub.publish({'x': np.float32(1.0), 'y': np.int64(3), 'z': np.array(2.5)})\n"
                "    bpub.publish({'data': np.bool_(True)})\n"
                "    try:\n        print('heard:', sub.get(timeout=0.25), flag.get(timeout=0.25))\n"
                "        break\n    except RosTimeoutError:\n        pass\n"
                "f32 = ros.advertise(NAME + '_f', 'std_msgs/msg/Float32')\n"
                "try:\n    f32.publish({'data': np.str_('1')})\n"
                "except InvalidMessageError as exc:\n    print(exc)\nros.close()", timeout=90)
    assert out.splitlines() == [
        "call: 6.0",
        "heard: {'x': 1.0, 'y': 3.0, 'z': 2.5} {'data': True}",
        f"publish to {topic}_f: data: expected float32, got numpy.str_ np.str_('1')",
    ]


@pytest.mark.usefixtures("kernel_env")
def test_an_interrupted_collect_keeps_its_messages(tmp_path: Path) -> None:
    """Interrupting a cell waiting in ``sub.collect(60)`` (Jupyter's stop button) keeps the
    messages it had collected in ``sub.collected``, and the interruption says so (the
    blocking client's, then ``await asub.collect(60)`` on the asyncio client)."""
    with notebooks.running_kernel(tmp_path) as (km, kc):
        notebooks.run_cell(kc, CELLS[0] + "\nimport threading, time\nfrom roslibpy_lite import sync\n"
                           "ros = sync.connect(URL)\npub = ros.advertise(NAME, 'std_msgs/msg/Int32')\n"
                           "count, armed = 0, None\n"
                           "def on_msg(msg):\n    global count\n    count += 1\n"
                           "    if armed is not None and count == armed + 5:\n"
                           "        print('five during collect', flush=True)\n"
                           "sub = ros.subscribe(NAME, 'std_msgs/msg/Int32', on_msg)\n"
                           "stop = threading.Event()\n"
                           "def publish():\n    i = 0\n    while not stop.is_set():\n"
                           "        pub.publish({'data': i})\n        i += 1\n        time.sleep(0.02)\n"
                           "threading.Thread(target=publish, daemon=True).start()\n"
                           "import roslibpy_lite\naros = await roslibpy_lite.connect(URL)\n"
                           "asub = await aros.subscribe(NAME, 'std_msgs/msg/Int32')\n"
                           "sub.next(timeout=30)\nawait asub.next(timeout=30)")
        for cell, stopped in (("sub.collect(60)", "KeyboardInterrupt"),
                              ("await asub.collect(60)", "CancelledError")):
            msg_id = kc.execute("armed = count\n" + cell, stop_on_error=False)
            while True:  # five messages arrived while collect waits
                msg = kc.get_iopub_msg(timeout=30)
                if msg["msg_type"] == "stream" and "five during collect" in msg["content"]["text"]:
                    break
            km.interrupt_kernel()
            reply = kc.get_shell_msg(timeout=30)
            assert reply["parent_header"]["msg_id"] == msg_id
            assert reply["content"]["ename"] == stopped
            assert "are in sub.collected" in "".join(reply["content"]["traceback"])
        out = notebooks.run_cell(kc, "stop.set()\nprint(len(sub.collected) >= 5, "
                                     "sub.collected[0]['data'] >= 0, len(asub.collected) >= 5)\n"
                                     "ros.close()\nawait aros.close()")
    assert out == "True True True\n"


@pytest.mark.usefixtures("kernel_env")
def test_a_misspelt_topic_names_the_right_one(tmp_path: Path) -> None:
    """``next()`` and ``get()`` timing out, and ``collect()`` ending empty, on a topic no
    node publishes name the published topic it resembles (either client)."""
    with notebooks.running_kernel(tmp_path) as (_, kc):
        out = notebooks.run_cell(
            kc, CELLS[0] + "\nimport warnings\nimport roslibpy_lite\nfrom roslibpy_lite import sync\n"
                "ros = sync.connect(URL)\naros = await roslibpy_lite.connect(URL)\n"
                "pub = ros.advertise(NAME + '_imu', 'std_msgs/msg/Int32')\n"
                "wrong = NAME + '_IMU'\n"
                "for _ in range(100):  # the graph shows the publisher (discovery has no event)\n"
                "    if (NAME + '_imu') in [t.name for t in ros.graph.topics()]:\n        break\n"
                "sub = ros.subscribe(wrong, 'std_msgs/msg/Int32')\n"
                "asub = await aros.subscribe(wrong, 'std_msgs/msg/Int32')\n"
                "for call in (lambda: sub.next(timeout=0.5), lambda: sub.get(timeout=0.5)):\n"
                "    try:\n        call()\n    except roslibpy_lite.RosTimeoutError as exc:\n"
                "        print(str(exc).replace(NAME, 'N'))\n"
                "try:\n    await asub.next(timeout=0.5)\n"
                "except roslibpy_lite.RosTimeoutError as exc:\n    print(str(exc).replace(NAME, 'N'))\n"
                "with warnings.catch_warnings(record=True) as caught:\n"
                "    warnings.simplefilter('always')\n"
                "    print(len(sub.collect(0.5)), len(await asub.collect(0.5)))\n"
                "for w in caught:\n    print(str(w.message).replace(NAME, 'N'))\n"
                "ros.close()\nawait aros.close()", timeout=90)
    hint = "nothing publishes N_IMU in the graph; did you mean 'N_imu'?"
    assert out.splitlines() == [
        f"no message on N_IMU within 0.5 s; {hint}",
        f"no message on N_IMU within 0.5 s; {hint}",
        f"no message on N_IMU within 0.5 s; {hint}",
        "0 0",
        f"collect from N_IMU: no message in 0.5 s; {hint}",
        f"collect from N_IMU: no message in 0.5 s; {hint}",
    ]


@pytest.mark.usefixtures("kernel_env")
def test_run_in_a_cell_says_await_and_show_state_leaves_no_value(tmp_path: Path) -> None:
    """In a kernel, ``roslibpy_lite.run(main())`` says to write ``await main()`` instead, and a
    cell ending with ``jupyter.show_state(ros)`` shows the state line and no ``Out`` value."""
    def outputs(kc: Any, code: str) -> list[dict[str, Any]]:
        seen: list[dict[str, Any]] = []
        reply = kc.execute_interactive(code, timeout=60, output_hook=seen.append)
        assert reply["content"]["status"] == "ok", reply["content"]
        return [m for m in seen if m["msg_type"] in ("stream", "display_data", "execute_result")]

    with notebooks.running_kernel(tmp_path) as (_, kc):
        ran = outputs(kc, CELLS[0] + "\nimport roslibpy_lite\nasync def main():\n    return 1\n"
                          "try:\n    roslibpy_lite.run(main())\n"
                          "except RuntimeError as exc:\n    print(exc)")
        shown = outputs(kc, "from roslibpy_lite import jupyter, sync\nros = sync.connect(URL)\n"
                            "jupyter.show_state(ros, label='robot')")
        notebooks.run_cell(kc, "ros.close()")
    assert [m["msg_type"] for m in ran] == ["stream"]
    assert "write `await main()` at the top level of the cell" in ran[0]["content"]["text"]
    assert [m["msg_type"] for m in shown] == ["display_data"], shown
    assert shown[0]["content"]["data"]["text/plain"].startswith("robot: connected since ")
