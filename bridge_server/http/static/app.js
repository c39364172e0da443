// The live status page: polls status.json once a second and redraws the tables. Rates carry
// their units and are the bridge's, averaged over the window status.json states; the plot
// draws the bridge's own history of the last 5 minutes, with its axes and scale.
"use strict";
(function () {
  const { el, duration, count, bytes, rate, poll } = window.statusPage;  // page.js
  // Beside the page: /status.json on a bridge, /robot1/status.json for a relay's robot1
  // (the page opened as /static/index.html asks the root).
  const STATUS = location.pathname.startsWith("/static/") ? "/status.json" : "status.json";

  function fill(id, rows, empty) {
    const table = document.getElementById(id);
    const labels = Array.from(table.querySelectorAll("thead th")).map((th) => th.textContent);
    const body = table.tBodies[0];
    const fresh = document.createElement("tbody");
    if (!rows.length) {
      const tr = el("tr");
      const td = el("td", empty, "empty");
      td.colSpan = labels.length;
      tr.appendChild(td);
      fresh.appendChild(tr);
    }
    for (const row of rows) {
      const tr = el("tr");
      row.forEach((cell, i) => {
        const td = cell instanceof Node ? wrap(cell) : el("td", cell);
        if (typeof cell === "number") td.className = "num";
        td.dataset.label = labels[i] || "";
        tr.appendChild(td);
      });
      fresh.appendChild(tr);
    }
    table.replaceChild(fresh, body);
  }

  function wrap(node) { const td = el("td"); td.appendChild(node); return td; }

  function list(items) {
    if (!items.length) return el("span", "–");
    const span = el("span");
    items.forEach((item, i) => {
      if (i) span.appendChild(document.createTextNode(", "));
      span.appendChild(el("code", item));
    });
    return span;
  }

  function queue(c) {
    const span = el("span");
    let fill = 0;
    for (const s of c.subscriptions) fill = Math.max(fill, s.queue_length ? s.queued / s.queue_length : 0);
    span.appendChild(document.createTextNode(String(c.queued)));
    const bar = el("span", undefined, "bar");
    const inner = el("i");
    inner.style.width = Math.round(100 * Math.min(fill, 1)) + "%";
    bar.appendChild(inner);
    bar.title = Math.round(100 * fill) + "% of the fullest queue";
    span.appendChild(bar);
    return span;
  }

  // Messages per second, and bytes per second when there are any: "10.0 msg/s · 1.2 KB/s".
  function flow(t, key) {
    const msgs = t[key + "_per_s"];
    const b = t[key + "_bytes_per_s"];
    return b ? rate(msgs, "msg") + " \u00b7 " + rate(b, "B") : rate(msgs, "msg");
  }

  // Whose page this is: the robot's name in the title and heading (a relay's page of the
  // robot, or a robot's own bridge with an uplink), the relay apart from the robot's nodes.
  function identify(s) {
    const up = s.relay_uplink;
    const robot = s.robot || (up && up.robot);
    const kind = s.relay ? "relay" : "bridge";
    document.title = (robot ? robot + " \u00b7 " : "") + "roslibpy-lite " + kind;
    document.getElementById("robot-name").textContent = robot ? robot + " \u00b7 " : "";
    document.getElementById("kind").textContent = kind;
    document.getElementById("relay-meta").hidden = !s.relay;
    document.getElementById("workers-meta").hidden = !!s.relay;
    document.getElementById("workers-section").hidden = !!s.relay;
    if (s.relay) {
      document.getElementById("relay-id").textContent = s.relay.id;
      document.getElementById("relay-pid").textContent = s.relay.pid;
    }
    document.getElementById("uplink-section").hidden = !up;
    if (up) {
      const since = up.since ? " since " + new Date(up.since * 1000).toLocaleTimeString() : "";
      const state = up.up && up.admitted ? "up" : up.up ? "open, not admitted" : "down";
      const box = document.getElementById("uplink");
      box.replaceChildren();
      for (const text of [
        "robot " + up.robot, "routers " + up.routers.join(", "),
        "uplink " + state + since,
        "sending " + rate(up.messages_per_s, "msg") + " \u00b7 " + rate(up.bytes_per_s, "B") +
          " (over " + up.rate_window_s + " s)",
        "sent " + count(up.messages) + " msg \u00b7 " + bytes(up.bytes),
      ]) box.appendChild(el("span", text, text.startsWith("uplink ") && state !== "up"
        ? "warn" : undefined));
      if (up.refusal) box.appendChild(el("span", up.refusal, "warn"));
    }
  }

  function render(s) {
    identify(s);
    document.getElementById("version").textContent = s.version;
    document.getElementById("uptime").textContent = duration(s.now - s.started);
    document.getElementById("client-count").textContent = count(s.clients.length);
    document.getElementById("worker-count").textContent = s.workers.length;
    if (s.rate_window_s) {
      document.getElementById("rate-window").textContent =
        `Rates are averaged over the last ${s.rate_window_s} s.`;
    }
    fill("clients", s.clients.map((c) => [
      c.id, c.protocol || "rosbridge", c.address, new Date(c.connected_at * 1000).toLocaleTimeString(),
      list(c.subscriptions.map((x) => x.topic)), list(c.publishes), list(c.serves),
      queue(c), c.dropped ? el("span", count(c.dropped), "warn") : 0,
    ]), "no clients connected");
    // Topics in use now, or with traffic in the last second; ones nobody uses any more
    // leave the table (their totals stay in /metrics).
    const topics = Object.keys(s.topics).filter((name) => {
      const t = s.topics[name];
      return t.in_use || t.ros_received_per_s || t.sent_per_s || t.published_per_s;
    }).sort();
    plotRates(s);
    fill("topics", topics.map((name) => {
      const t = s.topics[name];
      return [name, t.type || "?", t.subscribers || 0, rate(t.ros_received_per_s, "msg"),
        flow(t, "sent"), flow(t, "published"), count(t.drops || 0)];
    }), "no topics in use");
    fill("services", s.services.map((sv) => {
      const calls = s.service_calls[sv.name];
      let n = 0;
      if (calls) for (const k in calls.outcomes) n += calls.outcomes[k];
      return [sv.name, sv.type, sv.served_by, n];
    }), "no services served by clients");
    // goals: finished (by outcome, from the counters) plus those in flight now
    const inUse = {};
    for (const a of s.actions) inUse[a.name] = a;
    const actionNames = Object.keys(Object.assign({}, s.action_goals, inUse)).sort();
    fill("actions", actionNames.map((name) => {
      const a = inUse[name] || {};
      const goals = s.action_goals[name];
      let done = 0;
      if (goals) for (const k in goals.outcomes) done += goals.outcomes[k];
      const flying = a.goals || 0;
      return [name, a.type || "?", a.served_by || "ROS",
        flying ? `${done + flying} (${flying} running)` : done];
    }), "no actions");
    fill("workers", s.workers.map((w) => [w.index, w.pid, w.node, duration(s.now - w.started), w.clients]),
      "none");
  }

  // The bridge's history (status.json's history: one point a second, kept 5 minutes on the
  // server, so a fresh page shows them all): messages per second to and from clients, on
  // axes of time (minutes ago) and messages per second with a round scale.
  const SPAN_S = 300, H = 150, LEFT = 64, RIGHT = 8, TOP = 8, BOTTOM = 22;
  const NS = "http://www.w3.org/2000/svg";

  function niceMax(v) {
    const p = Math.pow(10, Math.floor(Math.log10(Math.max(v, 1))));
    for (const m of [1, 2, 5, 10]) if (m * p >= v) return m * p;
    return 10 * p;
  }

  function svgEl(tag, attrs, text) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    return e;
  }

  function plotRates(s) {
    const h = s.history || { t: [], to_clients_per_s: [], from_clients_per_s: [] };
    const svg = document.getElementById("rates-plot");
    const w = Math.max(svg.clientWidth || 600, 200);
    svg.setAttribute("viewBox", `0 0 ${w} ${H}`);
    const top = niceMax(Math.max(1, ...h.to_clients_per_s, ...h.from_clients_per_s));
    const x = (t) => LEFT + (w - LEFT - RIGHT) * (1 + Math.max(t - s.now, -SPAN_S) / SPAN_S);
    const y = (v) => TOP + (H - TOP - BOTTOM) * (1 - v / top);
    const axes = svg.querySelector(".axes");
    axes.replaceChildren();
    for (const v of [0, top / 2, top]) {
      axes.appendChild(svgEl("line", { x1: LEFT, x2: w - RIGHT, y1: y(v), y2: y(v),
        class: v ? "grid" : "axis" }));
      axes.appendChild(svgEl("text", { x: LEFT - 6, y: y(v) + 4, "text-anchor": "end",
        class: "y-label" }, v.toLocaleString("en-US", { maximumFractionDigits: 1 }) + " msg/s"));
    }
    for (let m = 5; m >= 0; m--) {
      const at = x(s.now - 60 * m);
      axes.appendChild(svgEl("line", { x1: at, x2: at, y1: TOP, y2: H - BOTTOM,
        class: m ? "grid" : "axis" }));
      axes.appendChild(svgEl("text", { x: at, y: H - 6, class: "x-label",
        "text-anchor": m === 5 ? "start" : m ? "middle" : "end" }, m ? `\u2212${m} min` : "now"));
    }
    const line = (values) => values.map((v, i) =>
      `${x(h.t[i]).toFixed(1)},${y(v).toFixed(1)}`).join(" ");
    svg.querySelector(".to-clients").setAttribute("points", line(h.to_clients_per_s));
    svg.querySelector(".from-clients").setAttribute("points", line(h.from_clients_per_s));
    const last = (values) => values.length ? values[values.length - 1] : 0;
    document.getElementById("rates-now").textContent =
      `${rate(last(h.to_clients_per_s), "msg")} to clients, ` +
      `${rate(last(h.from_clients_per_s), "msg")} from clients ` +
      `(scale 0 to ${count(top)} msg/s)`;
  }

  poll(STATUS, render);
})();
