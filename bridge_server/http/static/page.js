// What the bridge's status page (app.js) and the relay's (relay.js) share: making elements,
// showing durations, and polling their JSON once a second.
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

  return { el, duration, poll };
})();
