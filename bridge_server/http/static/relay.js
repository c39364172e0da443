// The relay's page: polls /status.json once a second and lists its robots, each linking to
// its own status page (/robots/<robot>/, the bridge's page, whatever the robot's name).
"use strict";
(function () {
  const { el, duration, poll } = window.statusPage;  // page.js

  function cell(value) {
    const td = value instanceof Node ? el("td") : el("td", value);
    if (value instanceof Node) td.appendChild(value);
    if (typeof value === "number") td.className = "num";
    return td;
  }

  // What a robot sent that the relay dropped (over its limits, or unreadable), by kind.
  function over(dropped) {
    const kinds = Object.entries(dropped || {});
    if (!kinds.length) return "–";
    return el("span", kinds.map(([k, n]) => k + " " + n).join(", "), "warn");
  }

  function render(s) {
    document.getElementById("relay-id").textContent = s.relay;
    document.getElementById("version").textContent = s.version;
    document.getElementById("uptime").textContent = duration(s.now - s.started);
    document.getElementById("robot-count").textContent = s.robots.length;
    document.getElementById("client-count").textContent =
      s.robots.reduce((n, r) => n + r.clients, 0);
    const body = document.createElement("tbody");
    for (const r of s.robots) {
      const link = el("a", r.name);
      link.href = "/robots/" + encodeURIComponent(r.name) + "/" + location.search;  // ?token=
      const tr = el("tr");
      tr.dataset.robot = r.name;
      for (const v of [link, r.present ? "yes" : el("span", "gone", "warn"), r.clients,
        r.topics_watched.join(", ") || "–", r.messages_from_robot, r.bytes_from_robot,
        r.messages_to_clients,
        r.bytes_to_clients, r.messages_from_clients, r.bytes_from_clients, r.drops,
        over(r.dropped)]) {
        tr.appendChild(cell(v));
      }
      body.appendChild(tr);
    }
    if (!s.robots.length) {
      const td = el("td", "no robot on this relay's Zenoh network", "empty");
      td.colSpan = 12;
      body.appendChild(el("tr")).appendChild(td);
    }
    const table = document.getElementById("robots");
    table.replaceChild(body, table.tBodies[0]);
  }

  poll("/status.json", render);
})();
