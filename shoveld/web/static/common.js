// Shared by the cab and office pages: the snapshot socket, the theme, number formats.
"use strict";
const screen = {
  snapshot: null,
  socketUp: false,
  shown: {},            // pass number -> Date.now() when it first appeared (latency bench)
  // Tonnes from kilograms, "-" where the message left the value out (null), never "0.0".
  tonnes(kg, digits = 1) { return kg === null || kg === undefined ? "-" : (kg / 1000).toFixed(digits); },
  t(kg, digits = 1) { const x = screen.tonnes(kg, digits); return x === "-" ? x : x + " t"; },
  // A count with its noun as a person writes it, "1 pass" / "2 passes" (as shoveld/words.py).
  n(k, one, many) { return `${k} ${k === 1 ? one : many}`; },
  // A truck's load: its weighed total, "≥" before it when a pass of it was not weighed
  // (the total is then a lower bound: shoveld/payload/trucks.py).
  load(tr, digits = 1) { return (tr.invalid_passes ? "≥ " : "") + screen.t(tr.total_kg, digits); },
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
  // A text's head, before its nth ": ": a health problem's "source: what" (nth 2), before
  // the why and what to do; a pass's reason for not being weighed (nth 1), what happened
  // before why. The whole text when it has no such colon.
  head(p, nth = 2) {
    let j = -2;
    for (let k = 0; k < nth; k++) {
      j = p.indexOf(": ", j + 2);
      if (j < 0) return p;
    }
    return p.slice(0, j);
  },
  // A text as shown: whole, or its head with " …" when something was cut. (Not named
  // "shown": that is the map of passes to the time they appeared, which the latency
  // bench reads; a method of that name replaced it.)
  clipped(p, whole, nth = 2) {
    const h = whole ? p : screen.head(p, nth);
    return h === p ? p : h + " …";
  },
  // Whether the page runs off the screen, or a panel of it scrolls (the cab's panels do
  // rather than push the page, on the 10-inch panels).
  overflows() {
    const d = document.documentElement;
    return d.scrollHeight > innerHeight + 1 || d.scrollWidth > innerWidth + 1 ||
      Array.from(document.querySelectorAll("main .panel")).some(e => e.scrollHeight > e.clientHeight + 1);
  },
  // Problems in whole where the screen has room for them, else their heads (the whole of
  // each where the pointer rests, or for a while after a tap: the cab's panel is touch):
  // several at once must not push the page off the screen. show(list, whole) writes
  // them; called once the rest of the page is drawn.
  fitProblems(probs, show, tapped = false) {
    show(probs, true);
    if (!tapped && probs.some(p => screen.head(p) !== p) && screen.overflows()) show(probs, false);
  },
  TAP_MS: 15000,  // how long a tap shows the problems whole
  // A tap on el shows the problems whole for TAP_MS (another tap, back to their heads);
  // tapped(key) says whether it still does.
  tappable(el, key = () => "", redraw = () => {}) {
    screen.tapUntil = screen.tapUntil || {};
    el.addEventListener("click", ev => {
      const k = key(ev);
      if (k === null) return;
      screen.tapUntil[k] = Date.now() < (screen.tapUntil[k] || 0) ? 0 : Date.now() + screen.TAP_MS;
      redraw();
    });
  },
  tapped(key = "") { return Date.now() < ((screen.tapUntil || {})[key] || 0); },
  // The link and health words: the page's own socket first, then Zenoh, then the shovel.
  problems(snap, shovel) {
    const out = [];
    if (!screen.socketUp) out.push("screen: lost the cab server, reconnecting ...");
    const linkDown = snap && snap.link !== "up";
    if (linkDown) out.push("zenoh: " + (snap.link_detail || snap.link));
    // the shovel's copy of the link's words ("link: down ...") is said once, above
    if (shovel) for (const p of shovel.problems) {
      if (!out.includes(p) && !(linkDown && p.startsWith("link: "))) out.push(p);
    }
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
