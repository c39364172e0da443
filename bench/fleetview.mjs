// Many fleet viewers in one Node process: bench/fleetview.py's viewers, for the sizes where
// Python's own websocket clients would take more of the machine than the tier they measure.
//
// The same plan, the same measurements and the same JSON lines as bench/fleetview.py (its
// module text says what each one is): `node bench/fleetview.mjs URL PLAN_JSON [--ramp S]
// [--wait S]` prints {"event": "ready", ...} once every connection got a message (or --wait
// passed), then answers each stdin line ({"cmd": "stats" | "reset" | "mark", "t": ...}) with
// one JSON line. Websockets from the `ws` package (installed by scripts/setup.sh beside the
// stock roslib client; NODE_PATH names it).
import { createRequire } from "node:module";
import { createInterface } from "node:readline";
import { performance } from "node:perf_hooks";

const WebSocket = createRequire(import.meta.url)("ws"); // a require honours NODE_PATH

// A closed connection dials again after roslibpy-lite's client's delays (as bench/fleetview.py,
// with roslibpy_lite.Backoff's defaults): 0.1 s doubling to 5 s while dials fail, each less a
// random share of up to half, from 0.1 s again once one opens.
const BACKOFF = { initial: 0.1, maximum: 5.0, factor: 2.0, jitter: 0.5 };
const RAMP_BATCH = 50; // connections dialed together, --ramp s apart
const LATENCY_KEEP = 2000; // latency samples kept per connection (and per robot in stats)

let odd = null; // the first message a viewer could not read (with its robot and topic)

const monotonic = () => performance.now() / 1000;
const wallMs = () => performance.timeOrigin + performance.now();

class Conn {
  constructor(base, robot, topic) {
    this.url = `${base}/${robot}`;
    this.robot = robot;
    this.topic = topic;
    this.counted = topic === "/pose" || topic === "/status";
    this.openS = null;
    this.firstS = null;
    this.lastSeq = null;
    this.got = this.missed = this.repeated = this.frames = this.malformed = 0;
    this.latencyMs = [];
    this.mark = null;
    this.backS = null;
    this.reconnects = 0;
    this.heard = false;
    this.onHeard = () => {}; // told once, at the first message
    this.attempts = 0; // dials failed since the last that opened
  }

  nextDelay() { // seconds before the next dial; counts the attempt
    const { initial, maximum, factor, jitter } = BACKOFF;
    const base = Math.min(maximum, initial * factor ** Math.min(this.attempts, 64));
    this.attempts += 1;
    return base * (1 - jitter * Math.random());
  }

  subscribeOp() {
    return JSON.stringify({
      op: "subscribe", topic: this.topic, queue_length: 2,
      ...(this.counted ? {} : { compression: "cbor-raw" }),
    });
  }

  run() {
    const t0 = monotonic();
    const ws = new WebSocket(this.url, {
      handshakeTimeout: 120_000, maxPayload: 2 ** 24, perMessageDeflate: false,
    });
    ws.on("open", () => {
      if (this.openS === null) this.openS = monotonic() - t0;
      this.attempts = 0;
      ws.send(this.subscribeOp());
    });
    ws.on("message", (data, isBinary) => this.on(data, isBinary, t0));
    ws.on("error", () => {}); // "close" follows
    ws.on("close", () => {
      this.reconnects += 1;
      setTimeout(() => this.run(), this.nextDelay() * 1000);
    });
  }

  on(data, isBinary, t0) {
    try {
      this.read(data, isBinary, t0);
    } catch (err) { // counted, one kept: a message the relay should not have sent
      this.malformed += 1;
      odd ??= `${this.robot} ${this.topic}: ${err}: ${data.toString().slice(0, 400)}`;
    }
  }

  read(data, isBinary, t0) {
    const now = monotonic();
    if (isBinary || !this.counted) { // cbor-raw: counted, not decoded
      this.frames += 1;
      this.arrived(now, t0);
      return;
    }
    const msg = JSON.parse(data.toString());
    if (msg.op !== "publish") return;
    const body = msg.msg;
    let seq, sentMs;
    if (this.topic === "/pose") {
      seq = Math.trunc(body.pose.position.x);
      const stamp = body.header.stamp;
      sentMs = stamp.sec * 1000 + stamp.nanosec / 1e6;
    } else {
      const status = JSON.parse(body.data);
      seq = Math.trunc(Number(status.seq));
      sentMs = Number(status.t) / 1e6;
    }
    this.arrived(now, t0);
    if (this.lastSeq !== null && seq <= this.lastSeq) {
      this.repeated += 1;
      return;
    }
    if (this.lastSeq !== null) this.missed += seq - this.lastSeq - 1;
    this.lastSeq = seq;
    this.got += 1;
    const lat = wallMs() - sentMs;
    if (this.latencyMs.length < LATENCY_KEEP) this.latencyMs.push(lat);
    else this.latencyMs[Math.floor(Math.random() * LATENCY_KEEP)] = lat;
  }

  arrived(now, t0) {
    if (this.firstS === null) this.firstS = now - t0;
    if (this.mark !== null && this.backS === null) this.backS = wallMs() / 1000 - this.mark;
    if (!this.heard) {
      this.heard = true;
      this.onHeard();
    }
  }

  reset() {
    this.got = this.missed = this.repeated = this.frames = this.malformed = 0;
    this.latencyMs = [];
  }
}

function sample(values, k) { // k of values, at random
  const out = values.slice();
  for (let i = out.length - 1; i > 0; i--) {
    const j = Math.floor(Math.random() * (i + 1));
    [out[i], out[j]] = [out[j], out[i]];
  }
  return out.slice(0, k);
}

function stats(conns) {
  const robots = {};
  for (const c of conns) {
    const r = robots[c.robot] ??= {
      got: 0, missed: 0, repeated: 0, frames: 0, malformed: 0, latency_ms: [], viewers: 0,
    };
    r.viewers += 1;
    r.got += c.got;
    r.missed += c.missed;
    r.repeated += c.repeated;
    r.frames += c.frames;
    r.malformed += c.malformed;
    r.latency_ms.push(...c.latencyMs);
  }
  for (const r of Object.values(robots)) {
    if (r.latency_ms.length > LATENCY_KEEP) r.latency_ms = sample(r.latency_ms, LATENCY_KEEP);
  }
  return {
    event: "stats", robots,
    open_s: conns.filter((c) => c.openS !== null).map((c) => c.openS),
    first_s: conns.filter((c) => c.firstS !== null).map((c) => c.firstS),
    back_s: conns.filter((c) => c.mark !== null).map((c) => c.backS),
    silent: conns.filter((c) => c.firstS === null).length,
    reconnects: conns.reduce((n, c) => n + c.reconnects, 0),
    odd,
  };
}

function option(args, name, fallback) {
  const i = args.indexOf(name);
  return i >= 0 ? Number(args[i + 1]) : fallback;
}

const sleep = (s) => new Promise((resolve) => setTimeout(resolve, s * 1000));

async function main(args) {
  const [url, planJson] = args;
  const ramp = option(args, "--ramp", 0.05);
  const wait = option(args, "--wait", 120);
  const conns = [];
  for (const [robots, topic] of JSON.parse(planJson)) {
    for (const robot of robots) conns.push(new Conn(url, robot, topic));
  }
  let unheard = conns.length;
  const allHeard = new Promise((resolve) => {
    for (const c of conns) c.onHeard = () => { if (--unheard === 0) resolve(); };
  });
  for (let k = 0; k < conns.length; k += RAMP_BATCH) { // a ramp, as viewers arrive
    for (const c of conns.slice(k, k + RAMP_BATCH)) c.run();
    await sleep(ramp);
  }
  await Promise.race([allHeard, sleep(wait)]);
  const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
  say({ event: "ready", connections: conns.length, silent: conns.filter((c) => !c.heard).length });
  for await (const line of createInterface({ input: process.stdin })) {
    const cmd = JSON.parse(line);
    if (cmd.cmd === "reset") {
      for (const c of conns) c.reset();
      say({ event: "reset" });
    } else if (cmd.cmd === "mark") {
      for (const c of conns) { c.mark = Number(cmd.t); c.backS = null; }
      say({ event: "marked" });
    } else {
      say(stats(conns));
    }
  }
  process.exit(0);
}

main(process.argv.slice(2));
