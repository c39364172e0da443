"""Drive stock roslibpy (PyPI, unchanged) from a test, one command per stdin line.

Run as ``python tests/peers/roslibpy_peer.py HOST PORT``. The process connects
with ``roslibpy.Ros(host, port)``, prints ``{"event": "ready", ...}`` and then
obeys JSON commands read from stdin, one per line::

    {"seq": 1, "cmd": "publish", "topic": "/x", "type": "std_msgs/String", "msg": {...}}

Every command is answered by one line ``{"seq": 1, "ok": true, "value": ...}``
or ``{"seq": 1, "ok": false, "error": "..."}``; things the bridge pushes
(messages on subscribed topics, requests to served services) are printed as
``{"event": ...}`` lines as they arrive. Commands run in their own threads and
use roslibpy's blocking API the way a user script does, so a slow one never
holds up the others. The process exits on ``close`` or at end of input.

Twisted's reactor runs once per process, which is why the tests run roslibpy
here, in a child process, and not in the pytest process.
"""

from __future__ import annotations

import json
import sys
import threading
from collections.abc import Callable, Mapping
from typing import Any

import roslibpy
from roslibpy.ros2 import Header

_out_lock = threading.Lock()


def emit(obj: dict[str, Any]) -> None:
    """Print one JSON line on stdout (thread-safe)."""
    line = json.dumps(obj, default=str)
    with _out_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def serve_setbool(args: dict[str, Any], response: dict[str, Any]) -> bool:
    """A std_srvs/SetBool server: succeeds with the request's value and says what it got."""
    data = bool(args.get("data"))
    response["success"] = data
    response["message"] = f"roslibpy got data={data}"
    return True


def serve_mult(args: dict[str, Any], response: dict[str, Any]) -> bool:
    """A mult_msgs/MultFloats server: the product of x and y."""
    response["result"] = float(args["x"]) * float(args["y"])
    return True


def serve_fail(args: dict[str, Any], response: dict[str, Any]) -> bool:
    """A server whose handler reports failure (roslibpy sends result false)."""
    return False


HANDLERS: dict[str, Callable[[dict[str, Any], dict[str, Any]], bool]] = {
    "setbool": serve_setbool,
    "mult": serve_mult,
    "fail": serve_fail,
}


class Peer:
    """One roslibpy connection and the topics and services it made, by name."""

    def __init__(self, host: str, port: int) -> None:
        self.ros = roslibpy.Ros(host, port)
        self.topics: dict[tuple[str, str, str | None], Any] = {}
        self.services: dict[str, Any] = {}

    def topic(self, cmd: dict[str, Any]) -> Any:
        """The roslibpy Topic for the command's (topic, type), made once with its options."""
        key = (cmd["topic"], cmd["type"], cmd.get("handle"))
        if key not in self.topics:
            names = ("latch", "queue_size", "compression", "throttle_rate", "queue_length")
            options = {k: cmd[k] for k in names if k in cmd}
            self.topics[key] = roslibpy.Topic(self.ros, cmd["topic"], cmd["type"], **options)
        return self.topics[key]

    def send_goal(self, cmd: dict[str, Any]) -> dict[str, Any]:
        """Send an action goal with roslibpy.ActionClient; wait for its result."""
        client = roslibpy.ActionClient(self.ros, cmd["action"], cmd["type"])
        feedback: list[Any] = []
        outcome: dict[str, Any] = {}

        def on_result(result: Any) -> None:
            outcome["result"] = result

        def on_error(error: Any) -> None:
            outcome["error"] = error

        sent: list[str] = []
        cancel_after_feedback = bool(cmd.get("cancel_after_feedback"))
        lock = threading.Lock()

        def on_feedback(values: Any) -> None:
            with lock:
                feedback.append(values)
                if cancel_after_feedback and len(feedback) == 1 and sent:
                    client.cancel_goal(sent[0])

        with lock:  # feedback waits until the goal id is known
            goal_id = client.send_goal(roslibpy.Goal(cmd["goal"]), on_result, on_feedback, on_error)
            sent.append(goal_id)
        client.wait_goal(goal_id, timeout=float(cmd.get("goal_timeout", 10.0)))
        if "error" in outcome:
            raise RuntimeError(f"goal failed: {outcome['error']}")
        result = outcome["result"]
        return {
            "status": result["status"].value,
            "values": result["values"],
            "feedback": [dict(f) for f in feedback],
        }

    def handle(self, cmd: dict[str, Any]) -> Any:
        """Carry out one command with the stock roslibpy API; returns the reply value."""
        op = cmd["cmd"]
        ros = self.ros
        timeout = float(cmd.get("timeout", 5.0))
        if op == "advertise":
            self.topic(cmd).advertise()
            return None
        if op == "publish":
            msg = dict(cmd["msg"])
            if cmd.get("ros2_header"):
                # What a roslibpy user writes: the stock ROS 2 Header helper (ROS 1 time keys).
                header = msg["header"]
                msg["header"] = Header(stamp=header["stamp"], frame_id=header["frame_id"])
            self.topic(cmd).publish(roslibpy.Message(msg))
            return None
        if op == "unadvertise":
            self.topic(cmd).unadvertise()
            return None
        if op == "subscribe":
            name, tag = cmd["topic"], cmd.get("handle")

            def on_message(msg: dict[str, Any], name: str = name, tag: Any = tag) -> None:
                emit({"event": "message", "topic": name, "handle": tag, "msg": msg})

            self.topic(cmd).subscribe(on_message)
            return None
        if op == "unsubscribe":
            self.topic(cmd).unsubscribe()
            return None
        if op == "send_goal":
            return self.send_goal(cmd)
        if op == "call":
            service = roslibpy.Service(ros, cmd["service"], cmd.get("type", ""))
            request = roslibpy.ServiceRequest(cmd.get("args", {}))
            return service.call(request, timeout=timeout)
        if op == "advertise_service":
            name = cmd["service"]
            handler = HANDLERS[cmd["handler"]]

            def on_request(args: dict[str, Any], response: dict[str, Any]) -> bool:
                emit({"event": "request", "service": name, "args": args})
                return handler(args, response)

            srv = roslibpy.Service(ros, name, cmd["type"])
            srv.advertise(on_request)
            self.services[name] = srv
            return None
        if op == "unadvertise_service":
            self.services.pop(cmd["service"]).unadvertise()
            return None
        if op == "get_topics":
            return ros.get_topics()
        if op == "get_topic_type":
            return ros.get_topic_type(cmd["topic"])
        if op == "get_topics_for_type":
            return ros.get_topics_for_type(cmd["type"])
        if op == "get_services":
            return ros.get_services()
        if op == "get_service_type":
            return ros.get_service_type(cmd["service"])
        if op == "get_services_for_type":
            return ros.get_services_for_type(cmd["type"])
        if op == "get_nodes":
            return ros.get_nodes()
        if op == "get_node_details":
            return ros.get_node_details(cmd["node"])
        if op == "get_time":
            stamp = ros.get_time()
            return {"secs": stamp.secs, "nsecs": stamp.nsecs}
        if op == "get_action_servers":
            done = threading.Event()
            found: list[Any] = []

            def on_servers(servers: Any) -> None:
                found.append(servers)
                done.set()

            ros.get_action_servers(on_servers)  # roslibpy offers only the callback form
            if not done.wait(timeout):
                raise TimeoutError("no answer to get_action_servers")
            return found[0]["action_servers"]  # the callback gets the whole response
        if op == "get_params":
            return ros.get_params()
        if op == "get_param":
            return ros.get_param(cmd["name"])
        if op == "set_param":
            ros.set_param(cmd["name"], cmd["value"])
            return None
        if op == "get_message_details":
            return ros.get_message_details(cmd["type"])
        if op == "get_service_request_details":
            return ros.get_service_request_details(cmd["type"])
        if op == "get_service_response_details":
            return ros.get_service_response_details(cmd["type"])
        if op == "is_connected":
            return bool(ros.is_connected)
        raise ValueError(f"unknown command {op!r}")


def plain(value: Any) -> Any:
    """roslibpy's UserDict results (ServiceResponse, Message...) as plain JSON values."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def run_command(peer: Peer, cmd: dict[str, Any]) -> None:
    """Run one command and print its reply, whatever happens."""
    seq = cmd.get("seq")
    try:
        value = plain(peer.handle(cmd))
    except Exception as exc:  # every failure goes back to the test as text
        emit({"seq": seq, "ok": False, "error": f"{type(exc).__name__}: {exc}"})
    else:
        emit({"seq": seq, "ok": True, "value": value})


def main() -> int:
    """Connect, announce readiness, obey commands until ``close`` or end of input."""
    host, port = sys.argv[1], int(sys.argv[2])
    peer = Peer(host, port)
    try:
        peer.ros.run(timeout=10)
    except Exception as exc:
        emit({"event": "connect_failed", "error": f"{type(exc).__name__}: {exc}"})
        return 2
    emit({
        "event": "ready", "client": "roslibpy", "version": roslibpy.__version__,
        "transport": type(peer.ros.factory).__name__,
    })
    for line in sys.stdin:
        if not line.strip():
            continue
        cmd = json.loads(line)
        if cmd.get("cmd") == "close":
            break
        threading.Thread(target=run_command, args=(peer, cmd), daemon=True).start()
    peer.ros.terminate()
    emit({"event": "closed"})
    return 0


if __name__ == "__main__":
    sys.exit(main())
