// The live status page: polls status.json once a second and redraws the tables.
"use strict";
(function () {
  const { el, duration, poll } = window.statusPage;  // page.js
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

  function rate(v) { return v === undefined ? "–" : Number(v).toFixed(1); }

  function render(s) {
    document.getElementById("version").textContent = s.version;
    document.getElementById("uptime").textContent = duration(s.now - s.started);
    document.getElementById("client-count").textContent = s.clients.length;
    document.getElementById("worker-count").textContent = s.workers.length;
    fill("clients", s.clients.map((c) => [
      c.id, c.protocol || "rosbridge", c.address, new Date(c.connected_at * 1000).toLocaleTimeString(),
      list(c.subscriptions.map((x) => x.topic)), list(c.publishes), list(c.serves),
      queue(c), c.dropped ? el("span", c.dropped, "warn") : 0,
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
      return [name, t.type || "?", t.subscribers || 0, rate(t.ros_received_per_s),
        rate(t.sent_per_s), rate(t.published_per_s), t.drops || 0];
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

  // The last PLOT_POINTS seconds of messages per second, in all: "is it still flowing?"
  const PLOT_POINTS = 300;
  const history = { toClients: [], fromClients: [] };

  function plotRates(s) {
    let out = 0, inn = 0;
    for (const name in s.topics) {
      out += s.topics[name].sent_per_s || 0;
      inn += s.topics[name].published_per_s || 0;
    }
    for (const [key, v] of [["toClients", out], ["fromClients", inn]]) {
      history[key].push(v);
      if (history[key].length > PLOT_POINTS) history[key].shift();
    }
    const svg = document.getElementById("rates-plot");
    const w = 600, h = 60;
    const top = Math.max(1, ...history.toClients, ...history.fromClients);
    const line = (values) => values.map((v, i) =>
      `${(w * (PLOT_POINTS - values.length + i) / (PLOT_POINTS - 1)).toFixed(1)},` +
      `${(h - 2 - (h - 4) * v / top).toFixed(1)}`).join(" ");
    svg.querySelector(".to-clients").setAttribute("points", line(history.toClients));
    svg.querySelector(".from-clients").setAttribute("points", line(history.fromClients));
    document.getElementById("rates-now").textContent =
      `${out.toFixed(1)} /s to clients, ${inn.toFixed(1)} /s from clients (peak ${top.toFixed(0)})`;
  }

  poll(STATUS, render);
})();
