// Drive the stock Foxglove WebSocket client (@foxglove/ws-protocol, npm, unchanged) from a
// test, one JSON command per stdin line; messages are decoded and encoded with
// @foxglove/rosmsg2-serialization from the schemas the bridge advertises.
//
//   node foxglove_peer.mjs ws://127.0.0.1:PORT[?token=...]
//
// The line protocol of peer.mjs: {"event":"ready", serverInfo} once the server said hello;
// each {"seq","cmd",...} is answered with {"seq","ok","value"|"error"}; what the server
// pushes arrives as {"event": ...} lines (message, status, advertise, parameterValues,
// connectionGraphUpdate, time, closed).

import * as readline from "node:readline";
import { readFileSync } from "node:fs";
import wsProtocol from "@foxglove/ws-protocol";
import { parse } from "@foxglove/rosmsg";
import { MessageReader, MessageWriter } from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const version = JSON.parse(
  readFileSync(new URL("./node_modules/@foxglove/ws-protocol/package.json", import.meta.url), "utf8"),
).version;

// Typed arrays and bigints have no JSON form of their own: tag them (as peer.mjs does).
// Bytes go as base64: a 640x480 image as 921,600 numbers took seconds to print and parse on
// a loaded machine, long enough for the next command's answer to miss its deadline.
function jsonValue(_key, value) {
  if (typeof value === "bigint") return { $bigint: value.toString() };
  if (value instanceof Uint8Array) {
    return { $bytes: Buffer.from(value.buffer, value.byteOffset, value.byteLength).toString("base64") };
  }
  if (ArrayBuffer.isView(value) && !(value instanceof DataView)) {
    return { $typed: value.constructor.name, values: Array.from(value, (v) => (typeof v === "bigint" ? v.toString() : v)) };
  }
  return value;
}

function emit(obj) {
  process.stdout.write(JSON.stringify(obj, jsonValue) + "\n");
}

const url = process.argv[2];
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // id -> channel
const services = new Map(); // name -> service
const subscriptions = new Map(); // topic -> subscription id
const readers = new Map(); // subscription id -> { topic, reader }
const clientChannels = new Map(); // topic -> { id, writer }
const calls = new Map(); // call id -> { resolve, reject, reader }
const waiters = []; // [predicate, resolve] for channels and services
let nextCallId = 1;
let serverInfo = null;

const definitions = (schema) => parse(schema, { ros2: true });

function settleWaiters() {
  for (let i = waiters.length - 1; i >= 0; i--) {
    const found = waiters[i][0]();
    if (found) {
      waiters[i][1](found);
      waiters.splice(i, 1);
    }
  }
}

function waitFor(find, what, timeoutMs) {
  const now = find();
  if (now) return Promise.resolve(now);
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`no ${what} within ${timeoutMs} ms`)), timeoutMs);
    waiters.push([find, (v) => { clearTimeout(timer); resolve(v); }]);
  });
}

const channelOf = (topic) => () => [...channels.values()].find((c) => c.topic === topic);
const serviceOf = (name) => () => services.get(name);

client.on("serverInfo", (info) => {
  serverInfo = info;
  emit({ event: "ready", client: "@foxglove/ws-protocol", version, serverInfo: info,
         protocol: ws.protocol });
  const lines = readline.createInterface({ input: process.stdin });
  lines.on("line", (line) => {
    if (!line.trim()) return;
    const cmd = JSON.parse(line);
    if (cmd.cmd === "close") shutdown(0);
    else run(cmd);
  });
  lines.on("close", () => shutdown(0));
});
client.on("advertise", (chans) => {
  for (const c of chans) channels.set(c.id, c);
  emit({ event: "advertise", channels: chans.map((c) => ({ id: c.id, topic: c.topic, schemaName: c.schemaName, encoding: c.encoding, schemaEncoding: c.schemaEncoding })) });
  settleWaiters();
});
client.on("unadvertise", (ids) => {
  for (const id of ids) channels.delete(id);
  emit({ event: "unadvertise", channelIds: ids });
});
client.on("advertiseServices", (list) => {
  for (const s of list) services.set(s.name, s);
  emit({ event: "advertiseServices", services: list.map((s) => ({ id: s.id, name: s.name, type: s.type })) });
  settleWaiters();
});
client.on("unadvertiseServices", (ids) => {
  for (const [name, s] of services) if (ids.includes(s.id)) services.delete(name);
  emit({ event: "unadvertiseServices", serviceIds: ids });
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = readers.get(subscriptionId);
  if (!sub) {
    emit({ event: "stray_message", subscriptionId });
    return;
  }
  let msg;
  try {
    msg = sub.reader.readMessage(data);
  } catch (err) {
    emit({ event: "decode_failed", topic: sub.topic, error: String(err) });
    return;
  }
  emit({ event: "message", topic: sub.topic, timestamp, bytes: data.byteLength, msg });
});
client.on("status", (s) => emit({ event: "status", level: s.level, message: s.message }));
client.on("time", (t) => emit({ event: "time", timestamp: t.timestamp }));
client.on("parameterValues", (p) => emit({ event: "parameterValues", id: p.id ?? null, parameters: p.parameters }));
client.on("connectionGraphUpdate", (u) => emit({ event: "connectionGraphUpdate", update: u }));
client.on("serviceCallResponse", (r) => {
  const call = calls.get(r.callId);
  if (!call) return;
  calls.delete(r.callId);
  try {
    call.resolve({ encoding: r.encoding, value: call.reader.readMessage(r.data) });
  } catch (err) {
    call.reject(err);
  }
});
client.on("serviceCallFailure", (f) => {
  const call = calls.get(f.callId);
  emit({ event: "serviceCallFailure", callId: f.callId, message: f.message });
  if (!call) return;
  calls.delete(f.callId);
  call.reject(new Error(`serviceCallFailure: ${f.message}`));
});
client.on("error", (err) => emit({ event: "error", error: String(err?.message ?? err) }));
client.on("close", (event) => {
  if (!serverInfo) emit({ event: "connect_failed", code: event?.code, reason: String(event?.reason ?? "") });
  else if (!closing) emit({ event: "disconnected", code: event?.code, reason: String(event?.reason ?? "") });
  if (!serverInfo) process.exit(2);
});

// Plain objects to what MessageWriter takes: {"$bytes": [..]} becomes a Uint8Array.
function revive(value) {
  if (Array.isArray(value)) return value.map(revive);
  if (value && typeof value === "object") {
    if (Array.isArray(value.$bytes)) return Uint8Array.from(value.$bytes);
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, revive(v)]));
  }
  return value;
}

async function handle(cmd) {
  const timeout = cmd.timeout_ms ?? 10000;
  switch (cmd.cmd) {
    case "wait_channel": {
      const c = await waitFor(channelOf(cmd.topic), `channel ${cmd.topic}`, timeout);
      return { id: c.id, topic: c.topic, encoding: c.encoding, schemaName: c.schemaName, schemaEncoding: c.schemaEncoding, schema: c.schema };
    }
    case "subscribe": {
      const c = await waitFor(channelOf(cmd.topic), `channel ${cmd.topic}`, timeout);
      const id = client.subscribe(c.id);
      subscriptions.set(cmd.topic, id);
      readers.set(id, { topic: cmd.topic, reader: new MessageReader(definitions(c.schema)) });
      return id;
    }
    case "unsubscribe": {
      const id = subscriptions.get(cmd.topic);
      client.unsubscribe(id);
      subscriptions.delete(cmd.topic);
      return id;
    }
    case "advertise": {
      const id = client.advertise({ topic: cmd.topic, encoding: cmd.encoding ?? "cdr", schemaName: cmd.schemaName, schema: cmd.schema, schemaEncoding: "ros2msg" });
      clientChannels.set(cmd.topic, { id, writer: cmd.schema ? new MessageWriter(definitions(cmd.schema)) : null });
      return id;
    }
    case "publish": {
      const ch = clientChannels.get(cmd.topic);
      const data = ch.writer ? ch.writer.writeMessage(revive(cmd.msg)) : new TextEncoder().encode(JSON.stringify(cmd.msg));
      client.sendMessage(ch.id, data);
      return data.byteLength;
    }
    case "publish_bytes": {
      const ch = clientChannels.get(cmd.topic);
      client.sendMessage(ch?.id ?? cmd.channel, Uint8Array.from(Buffer.from(cmd.hex, "hex")));
      return null;
    }
    case "unadvertise": {
      const ch = clientChannels.get(cmd.topic);
      client.unadvertise(ch.id);
      clientChannels.delete(cmd.topic);
      return ch.id;
    }
    case "call_service": {
      const s = await waitFor(serviceOf(cmd.service), `service ${cmd.service}`, timeout);
      const writer = new MessageWriter(definitions(s.request?.schema ?? s.requestSchema));
      const reader = new MessageReader(definitions(s.response?.schema ?? s.responseSchema));
      const callId = nextCallId++;
      const answer = new Promise((resolve, reject) => calls.set(callId, { resolve, reject, reader }));
      client.sendServiceCallRequest({ serviceId: s.id, callId, encoding: "cdr", data: new DataView(writer.writeMessage(revive(cmd.request)).buffer) });
      return answer;
    }
    case "call_service_id": {
      const callId = nextCallId++;
      const answer = new Promise((resolve, reject) => calls.set(callId, { resolve, reject, reader: null }));
      client.sendServiceCallRequest({ serviceId: cmd.service_id, callId, encoding: cmd.encoding ?? "cdr", data: new DataView(Uint8Array.from(Buffer.from(cmd.hex ?? "", "hex")).buffer) });
      return answer;
    }
    case "service": {
      const s = await waitFor(serviceOf(cmd.service), `service ${cmd.service}`, timeout);
      return { id: s.id, name: s.name, type: s.type, request: s.request, response: s.response };
    }
    case "get_parameters":
      client.getParameters(cmd.names, cmd.id);
      return null;
    case "set_parameters":
      client.setParameters(cmd.parameters, cmd.id);
      return null;
    case "subscribe_parameters":
      client.subscribeParameterUpdates(cmd.names);
      return null;
    case "subscribe_graph":
      client.subscribeConnectionGraph();
      return null;
    case "send_text":
      ws.send(cmd.text);
      return null;
    case "send_binary":
      ws.send(Buffer.from(cmd.hex, "hex"));
      return null;
    case "send_big": {
      // binary client message data of `size` payload bytes on channel `channel`
      const frame = Buffer.alloc(5 + cmd.size);
      frame.writeUInt8(1, 0);
      frame.writeUInt32LE(cmd.channel, 1);
      ws.send(frame);
      return frame.length;
    }
    case "is_open":
      return ws.readyState === WebSocket.OPEN;
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
  if (ws.readyState !== WebSocket.OPEN) bye();
  ws.on("close", bye);
  client.close();
  setTimeout(bye, 3000).unref();
}
