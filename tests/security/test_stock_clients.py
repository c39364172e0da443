"""Stock clients over wss:// with a token: roslibpy (headers=, is_secure=True) and roslib (npm).

Each runs as a small child program: it connects over TLS (trusting the test CA
through the usual environment variables), lists topics, tries to publish as a
viewer, lists topics again (so the bridge has handled the publish) and exits.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from typing import Any

import pytest

from tests.helpers import BridgeProcess, ros_env
from tests.peers.peer import NODE_DIR
from tests.security.support import AuthFile, Certs

ROSLIBPY_SCRIPT = """
import json, os, roslibpy
ros = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["PORT"]), is_secure=True,
                   headers={"Authorization": "Bearer " + os.environ["TOKEN"]})
ros.run(timeout=15)
topics = ros.get_topics()
roslibpy.Topic(ros, "/chatter_roslibpy", "std_msgs/msg/String").publish(
    roslibpy.Message({"data": "from a viewer"}))
ros.get_topics()
print(json.dumps({"topics": topics}), flush=True)
ros.terminate()
"""

ROSLIB_SCRIPT = """
import * as ROSLIB from "roslib";
const out = (o) => process.stdout.write(JSON.stringify(o) + "\\n");
const ros = new ROSLIB.Ros({});
ros.on("error", (e) => { out({ event: "error", error: String(e?.message ?? e) }); process.exit(1); });
ros.on("connection", () => {
  if (process.env.MODE === "auth") {
    ros.authenticate(process.env.TOKEN, "client", "dest", "rand", 0, "user", 0);
  }
  ros.getTopics((result) => {
    new ROSLIB.Topic({ ros, name: "/chatter_roslib", messageType: "std_msgs/msg/String" })
      .publish({ data: "from a viewer" });
    ros.getTopics(() => { out({ topics: result.topics }); process.exit(0); });
  }, (err) => { out({ error: String(err) }); process.exit(1); });
});
const url = process.env.MODE === "query" ? `${process.env.URL}/?token=${process.env.TOKEN}`
                                         : process.env.URL;
ros.connect(url);
"""


def _run(argv: list[str], cwd: Any, **env: str) -> dict[str, Any]:
    out = subprocess.run(argv, cwd=cwd, env=ros_env(**env), capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def test_roslibpy_over_wss_with_a_bearer_header(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile
) -> None:
    """roslibpy (is_secure=True, headers=) connects with a token; its viewer publish is refused."""
    start = len(tls_bridge.lines)
    result = _run([sys.executable, "-c", ROSLIBPY_SCRIPT], None, PORT=str(tls_bridge.port),
                  TOKEN=auth.tokens["viewer"], SSL_CERT_FILE=str(certs.ca))
    assert "/rosout" in result["topics"]
    tls_bridge.wait_for_line(r"forbidden: role viewer may not publish on /chatter_roslibpy",
                             start=start)


@pytest.mark.parametrize("mode", ["query", "auth"])
def test_roslib_over_wss_with_a_token(
    tls_bridge: BridgeProcess, certs: Certs, auth: AuthFile, mode: str
) -> None:
    """roslib from npm connects over wss with ?token= or authenticate(); a viewer publish is refused."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not on PATH: the roslib (npm) tests need Node.js 20+")
    start = len(tls_bridge.lines)
    result = _run([node, "--input-type=module", "-e", ROSLIB_SCRIPT], NODE_DIR,
                  URL=f"wss://127.0.0.1:{tls_bridge.port}", TOKEN=auth.tokens["viewer"],
                  MODE=mode, NODE_EXTRA_CA_CERTS=str(certs.ca))
    assert "/rosout" in result["topics"]
    tls_bridge.wait_for_line(r"forbidden: role viewer may not publish on /chatter_roslib",
                             start=start)
