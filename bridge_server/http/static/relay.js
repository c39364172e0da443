// The relay's page: polls /status.json once a second and lists its robots, each linking to
// its own status page (/robots/<robot>/, the bridge's page, whatever the robot's name).
// Counts carry their units and thousands separators, each beside its rate (averaged by the
// relay over the window status.json states).
"use strict";
(function () {
  const { el, duration, count, rateOver, poll } = window.statusPage;  // page.js

  function cell(value) {
    const td = value instanceof Node ? el("td") : el("td", value);
    if (value instanceof Node) td.appendChild(value);
    if (typeof value === "number") { td.className = "num"; td.textContent = count(value); }
    return td;
  }

  // What a robot sent that the relay dropped (over its limits, or unreadable), by kind.
  function over(dropped) {
    const kinds = Object.entries(dropped || {});
    if (!kinds.length) return "\u2013";
    return el("span", kinds.map(([k, n]) => k + " " + count(n)).join(", "), "warn");
  }

  // Messages and bytes one way: "12.0 msg/s · 1.2 MB/s" over "191,724 msg · 183.0 MB".
  function traffic(r, key) {
    const rates = r.rates || {};
    const div = el("div", undefined, "traffic");
    div.appendChild(rateOver(rates[`messages_${key}_per_s`], r[`messages_${key}`], "msg"));
    div.appendChild(rateOver(rates[`bytes_${key}_per_s`], r[`bytes_${key}`], "B"));
    div.dataset.messages = String(r[`messages_${key}`]);
    div.dataset.bytes = String(r[`bytes_${key}`]);
    return div;
  }

  function render(s) {
    document.getElementById("relay-id").textContent = s.relay;
    document.title = "relay " + s.relay + " \u00b7 roslibpy-lite";
    document.getElementById("version").textContent = s.version;
    document.getElementById("uptime").textContent = duration(s.now - s.started);
    document.getElementById("robot-count").textContent = s.robots.length;
    document.getElementById("client-count").textContent =
      count(s.robots.reduce((n, r) => n + r.clients, 0));
    if (s.rate_window_s) {
      document.getElementById("rate-window").textContent =
        `Rates are averaged over the last ${s.rate_window_s} s.`;
    }
    const body = document.createElement("tbody");
    for (const r of s.robots) {
      const link = el("a", r.name);
      link.href = "/robots/" + encodeURIComponent(r.name) + "/" + location.search;  // ?token=
      const tr = el("tr");
      tr.dataset.robot = r.name;
      for (const v of [link, r.present ? "yes" : el("span", "gone", "warn"), r.clients,
        r.topics_watched.join(", ") || "\u2013", traffic(r, "from_robot"),
        traffic(r, "to_clients"), traffic(r, "from_clients"), r.drops, over(r.dropped)]) {
        tr.appendChild(cell(v));
      }
      body.appendChild(tr);
    }
    if (!s.robots.length) {
      const td = el("td", "no robot on this relay's Zenoh network", "empty");
      td.colSpan = 9;
      body.appendChild(el("tr")).appendChild(td);
    }
    const table = document.getElementById("robots");
    table.replaceChild(body, table.tBodies[0]);
  }

  poll("/status.json", render);
})();
