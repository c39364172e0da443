// Drive stock roslib (npm, unchanged) from a test, one JSON command per stdin line.
//
//   node peer.mjs ws://127.0.0.1:PORT
//
// Same line protocol as ../roslibpy_peer.py: prints {"event":"ready",...} once
// connected, answers each {"seq","cmd",...} with {"seq","ok","value"|"error"},
// and prints {"event":...} lines for what the bridge pushes (topic messages,
// requests to served services). Exits on {"cmd":"close"} or end of input.
//
// WebSocket: roslib 2.x uses the global WebSocket when there is one (Node 22+,
// or Node 20 with --experimental-websocket) and its own dependency `ws`
// otherwise. The ready event says which one this run used.

import * as readline from "node:readline";
import { readFileSync } from "node:fs";
import * as ROSLIB from "roslib";

const roslibVersion = JSON.parse(
  readFileSync(new URL("./node_modules/roslib/package.json", import.meta.url), "utf8"),
).version;
const transport = typeof WebSocket === "function" ? "native WebSocket" : "ws package";

// Typed arrays (what roslib's CBOR decoder makes of RFC 8746 arrays and byte
// strings) and bigints have no JSON form of their own: tag them so the test
// can see exactly what the client decoded.
function jsonValue(_key, value) {
  if (typeof value === "bigint") return { $bigint: value.toString() };
  if (ArrayBuffer.isView(value) && !(value instanceof DataView)) {
    return { $typed: value.constructor.name, values: Array.from(value, (v) => (typeof v === "bigint" ? v.toString() : v)) };
  }
  return value;
}

function emit(obj) {
  process.stdout.write(JSON.stringify(obj, jsonValue) + "\n");
}

const handlers = {
  // std_srvs/SetBool: succeed with the request's value and say what came in.
  setbool(args, response) {
    const data = Boolean(args.data);
    response.success = data;
    response.message = `roslibjs got data=${data ? "True" : "False"}`;
    return true;
  },
  // mult_msgs/MultFloats: the product of x and y.
  mult(args, response) {
    response.result = Number(args.x) * Number(args.y);
    return true;
  },
  // A handler that reports failure (roslib sends result false).
  fail() {
    return false;
  },
};

const url = process.argv[2];
const ros = new ROSLIB.Ros({});
const topics = new Map();
const services = new Map();

function topic(cmd) {
  const key = `${cmd.topic}\u0000${cmd.type}\u0000${cmd.handle ?? ""}`;
  if (!topics.has(key)) {
    // A null type means the user left messageType out (roslib then sends no "type").
    const options = { ros, name: cmd.topic, messageType: cmd.type ?? undefined };
    for (const k of ["latch", "queue_size", "compression", "throttle_rate", "queue_length"]) {
      if (k in cmd) options[k] = cmd[k];
    }
    topics.set(key, new ROSLIB.Topic(options));
  }
  return topics.get(key);
}

// Report every `status` op the bridge sends. roslib itself only re-emits them as
// "status:<id>" events that nothing listens to; listening on the transport's
// parsed messages observes them without changing the library.
function watchStatuses(transport) {
  transport.on("message", (msg) => {
    if (msg?.op !== "status") return;
    const id = typeof msg.id === "string" ? msg.id : null;
    emit({ event: "status", about: id ? id.split(":")[0] : null, id, msg });
  });
}

const actionHandlers = {
  // test_msgs/action/Fibonacci: feedback with the sequence so far, then the result.
  fibonacci(action, goal, id) {
    const sequence = [0, 1];
    for (let i = 1; i < goal.order; i++) {
      sequence.push(sequence[i] + sequence[i - 1]);
      action.sendFeedback(id, { sequence: [...sequence] });
    }
    action.setSucceeded(id, { sequence });
  },
  // Feedback every 50 ms until ROS cancels the goal (see stopGoal).
  until_canceled(action, goal, id) {
    const sequence = [0, 1];
    runningGoals.set(id, setInterval(() => action.sendFeedback(id, { sequence }), 50));
  },
};

const runningGoals = new Map();

// roslib's cancel callback for served actions: end a running goal as canceled.
function stopGoal(action, id) {
  clearInterval(runningGoals.get(id));
  runningGoals.delete(id);
  emit({ event: "canceled", id });
  action.setCanceled(id, { sequence: [0, 1] });
}

// Wrap roslib's callback-style API in a promise (success value, or an Error with the text).
function viaCallbacks(start) {
  return new Promise((resolve, reject) => {
    start(resolve, (err) => reject(new Error(typeof err === "string" ? err : JSON.stringify(err))));
  });
}

async function handle(cmd) {
  switch (cmd.cmd) {
    case "advertise": {
      const t = topic(cmd);
      t.advertise();
      return null;
    }
    case "publish": {
      const t = topic(cmd);
      t.publish(cmd.msg);
      return null;
    }
    case "unadvertise":
      topic(cmd).unadvertise();
      return null;
    case "subscribe": {
      const name = cmd.topic;
      const t = topic(cmd);
      const tag = cmd.handle ?? null;
      t.subscribe((msg) => emit({ event: "message", topic: name, handle: tag, msg }));
      return null;
    }
    case "unsubscribe":
      topic(cmd).unsubscribe();
      return null;
    case "send_goal": {
      const action = new ROSLIB.Action({ ros, name: cmd.action, actionType: cmd.type });
      const feedback = [];
      return new Promise((resolve, reject) => {
        const id = action.sendGoal(
          cmd.goal,
          (values) => resolve({ status: 4, values, feedback }),
          (values) => {
            feedback.push(values);
            if (cmd.cancel_after_feedback && feedback.length === 1) action.cancelGoal(id);
          },
          (err) => reject(new Error(String(err))),
        );
        // roslib itself ignores a `status` about the goal and would wait forever.
        ros.on(`status:${id}`, (msg) => {
          if (msg.level === "error") reject(new Error(`status error: ${msg.msg}`));
        });
      });
    }
    case "advertise_action": {
      const handler = actionHandlers[cmd.handler];
      if (!handler) throw new Error(`unknown action handler ${cmd.handler}`);
      const action = new ROSLIB.Action({ ros, name: cmd.action, actionType: cmd.type });
      action.advertise(
        (goal, id) => {
          emit({ event: "goal", action: cmd.action, goal });
          handler(action, goal, id);
        },
        (id) => stopGoal(action, id),
      );
      return null;
    }
    case "get_action_servers":
      return viaCallbacks((ok, fail) => ros.getActionServers(ok, fail));
    case "get_publishers": {
      const t = topic(cmd);
      return viaCallbacks((ok, fail) => t.getPublishers(ok, fail));
    }
    case "get_params":
      return viaCallbacks((ok, fail) => ros.getParams(ok, fail));
    case "get_param": {
      const param = new ROSLIB.Param({ ros, name: cmd.name });
      return viaCallbacks((ok, fail) => param.get(ok, fail));
    }
    case "set_param": {
      const param = new ROSLIB.Param({ ros, name: cmd.name });
      return viaCallbacks((ok, fail) => param.set(cmd.value, () => ok(null), fail));
    }
    case "get_message_details": {
      const typedefs = await viaCallbacks((ok, fail) => ros.getMessageDetails(cmd.type, ok, fail));
      // What a roslib app does with them next: decode into a nested field -> type object.
      const problems = [];
      const onError = (e) => problems.push(String(e));
      ros.on("error", onError);
      let decoded;
      try {
        decoded = ros.decodeTypeDefs(typedefs);
      } finally {
        ros.off("error", onError);
      }
      return { typedefs, decoded, problems };
    }
    case "get_service_request_details":
      return viaCallbacks((ok, fail) => ros.getServiceRequestDetails(cmd.type, ok, fail));
    case "get_service_response_details":
      return viaCallbacks((ok, fail) => ros.getServiceResponseDetails(cmd.type, ok, fail));
    case "get_topics_and_raw_types":
      return viaCallbacks((ok, fail) => ros.getTopicsAndRawTypes(ok, fail));
    case "call": {
      const service = new ROSLIB.Service({ ros, name: cmd.service, serviceType: cmd.type ?? "" });
      return viaCallbacks((ok, fail) => service.callService(cmd.args ?? {}, ok, fail, cmd.call_timeout));
    }
    case "advertise_service": {
      const name = cmd.service;
      const handler = handlers[cmd.handler];
      if (!handler) throw new Error(`unknown handler ${cmd.handler}`);
      const service = new ROSLIB.Service({ ros, name, serviceType: cmd.type });
      if (cmd.async) {
        // The promise-based form: the handler returns the response values.
        await service.advertiseAsync(async (args) => {
          emit({ event: "request", service: name, args });
          const response = {};
          if (!handler(args, response)) throw new Error("handler failed");
          return response;
        });
      } else {
        await service.advertise((args, response) => {
          emit({ event: "request", service: name, args });
          return handler(args, response);
        });
      }
      services.set(name, service);
      return null;
    }
    case "unadvertise_service": {
      const service = services.get(cmd.service);
      services.delete(cmd.service);
      await service.unadvertise();
      return null;
    }
    case "get_topics":
      return viaCallbacks((ok, fail) => ros.getTopics(ok, fail));
    case "get_topic_type":
      return viaCallbacks((ok, fail) => ros.getTopicType(cmd.topic, ok, fail));
    case "get_topics_for_type":
      return viaCallbacks((ok, fail) => ros.getTopicsForType(cmd.type, ok, fail));
    case "get_services":
      return viaCallbacks((ok, fail) => ros.getServices(ok, fail));
    case "get_service_type":
      return viaCallbacks((ok, fail) => ros.getServiceType(cmd.service, ok, fail));
    case "get_services_for_type":
      return viaCallbacks((ok, fail) => ros.getServicesForType(cmd.type, ok, fail));
    case "get_nodes":
      return viaCallbacks((ok, fail) => ros.getNodes(ok, fail));
    case "get_node_details":
      return viaCallbacks((ok, fail) => ros.getNodeDetails(cmd.node, ok, fail));
    case "is_connected":
      return ros.isConnected;
    default:
      throw new Error(`unknown command ${cmd.cmd}`);
  }
}

function run(cmd) {
  handle(cmd).then(
    (value) => emit({ seq: cmd.seq, ok: true, value: value ?? null }),
    (err) => emit({ seq: cmd.seq, ok: false, error: String(err?.message ?? err) }),
  );
}

let closing = false;
function shutdown(code) {
  if (closing) return;
  closing = true;
  const bye = () => {
    emit({ event: "closed" });
    process.exit(code);
  };
  if (!ros.isConnected) bye();
  ros.on("close", bye);
  ros.close();
  setTimeout(bye, 3000).unref();
}

ros.on("error", (err) => {
  if (!ros.isConnected && !closing) {
    emit({ event: "connect_failed", error: String(err?.message ?? err) });
    process.exit(2);
  }
  emit({ event: "error", error: String(err?.message ?? err) });
});
ros.on("connection", () => {
  watchStatuses(ros.transport);
  emit({ event: "ready", client: "roslib", version: roslibVersion, transport });
  const lines = readline.createInterface({ input: process.stdin });
  lines.on("line", (line) => {
    if (!line.trim()) return;
    const cmd = JSON.parse(line);
    if (cmd.cmd === "close") shutdown(0);
    else run(cmd);
  });
  lines.on("close", () => shutdown(0));
});
ros.on("close", () => {
  if (!closing) emit({ event: "disconnected" });
});
ros.connect(url).catch((err) => {
  emit({ event: "connect_failed", error: String(err?.message ?? err) });
  process.exit(2);
});
