// What the bridge's status page (app.js) and the relay's (relay.js) share: making elements,
// showing durations, counts, bytes and rates with their units, and polling their JSON
// once a second.
"use strict";
window.statusPage = (function () {
  const POLL_MS = 1000;

  function el(tag, text, cls) {
    const e = document.createElement(tag);
    if (text !== undefined) e.textContent = String(text);
    if (cls) e.className = cls;
    return e;
  }

  function duration(seconds) {
    seconds = Math.max(0, Math.floor(seconds));
    const d = Math.floor(seconds / 86400), h = Math.floor(seconds / 3600) % 24;
    const m = Math.floor(seconds / 60) % 60, s = seconds % 60;
    if (d) return d + "d " + h + "h";
    if (h) return h + "h " + m + "m";
    if (m) return m + "m " + s + "s";
    return s + "s";
  }

  const NUMBER = new Intl.NumberFormat("en-US");
  const UNITS = ["B", "KB", "MB", "GB", "TB"];

  // 191724964 -> "191,724,964"
  function count(n) { return NUMBER.format(Math.round(Number(n) || 0)); }

  // Bytes in decimal units: 191724964 -> "191.7 MB"
  function bytes(n) {
    let v = Number(n) || 0, i = 0;
    while (v >= 1000 && i < UNITS.length - 1) { v /= 1000; i++; }
    return (i ? v.toFixed(1) : String(Math.round(v))) + " " + UNITS[i];
  }

  // A rate with its unit ("10.0 msg/s", "1.2 MB/s"); "–" before one was measured.
  function rate(v, unit) {
    if (v === undefined || v === null) return "\u2013";
    if (unit === "B") return bytes(v) + "/s";
    return Number(v).toLocaleString("en-US", { minimumFractionDigits: 1,
      maximumFractionDigits: 1 }) + " " + unit + "/s";
  }

  // A cell of a rate over its total below it: "10.0 msg/s" over "12,345 msg".
  function rateOver(perS, total, unit) {
    const div = el("div", undefined, "pair");
    div.appendChild(el("span", rate(perS, unit), "now"));
    div.appendChild(el("span", unit === "B" ? bytes(total) : count(total) + " " + unit,
      "total"));
    return div;
  }

  // Fetch url (with the page's ?token=) once a second, hand the JSON to render, and say in
  // #updated whether the page is live; body[data-updates] counts the renders (for tests).
  function poll(url, render) {
    async function once() {
      const updated = document.getElementById("updated");
      try {
        const r = await fetch(url + location.search, { cache: "no-store" });
        if (!r.ok) throw new Error(r.status + " " + r.statusText);
        render(await r.json());
        updated.textContent = "live · " + new Date().toLocaleTimeString();
        updated.className = "";
        document.body.dataset.updates = String(Number(document.body.dataset.updates || 0) + 1);
      } catch (err) {
        updated.textContent = "not updating: " + err.message;
        updated.className = "stale";
      }
      setTimeout(once, POLL_MS);
    }
    once();
  }

  return { el, duration, count, bytes, rate, rateOver, poll };
})();
