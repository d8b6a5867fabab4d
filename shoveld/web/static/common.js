// Shared by the cab and office pages: the snapshot socket, the theme, number formats.
"use strict";
const screen = {
  snapshot: null,
  socketUp: false,
  shown: {},            // pass number -> Date.now() when it first appeared (latency bench)
  t(kg, digits = 1) { return kg === null || kg === undefined ? "-" : (kg / 1000).toFixed(digits) + " t"; },
  // A count with its noun as a person writes it, "1 pass" / "2 passes" (as shoveld/words.py).
  n(k, one, many) { return `${k} ${k === 1 ? one : many}`; },
  esc(s) { return String(s ?? "").replace(/[&<>"]/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"}[c])); },
  connect(render) {
    const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws";
    let delay = 500;
    const open = () => {
      const ws = new WebSocket(url);
      ws.onopen = () => { screen.socketUp = true; delay = 500; };
      ws.onmessage = ev => { screen.snapshot = JSON.parse(ev.data); render(screen.snapshot); };
      ws.onclose = () => {
        screen.socketUp = false;
        render(screen.snapshot);
        setTimeout(open, delay);
        delay = Math.min(delay * 2, 5000);
      };
    };
    open();
  },
  // The link and health words: the page's own socket first, then Zenoh, then the shovel.
  problems(snap, shovel) {
    const out = [];
    if (!screen.socketUp) out.push("screen: lost the cab server, reconnecting ...");
    if (snap && snap.link !== "up") out.push("zenoh: " + (snap.link_detail || snap.link));
    if (shovel) for (const p of shovel.problems) if (!out.includes(p)) out.push(p);
    return out;
  },
  theme() {
    const btn = document.getElementById("theme");
    const apply = night => {
      document.body.classList.toggle("night", night);
      btn.textContent = night ? "Day" : "Night";
    };
    apply(localStorage.getItem("shoveld-theme") === "night");
    btn.onclick = () => {
      const night = !document.body.classList.contains("night");
      localStorage.setItem("shoveld-theme", night ? "night" : "day");
      apply(night);
    };
  },
};
