// The cab page: draws one shovel's snapshot (see shoveld/web/state.py for its fields).
"use strict";
const $ = id => document.getElementById(id);
const wanted = new URLSearchParams(location.search).get("shovel");

function pick(snap) {
  if (!snap || !snap.shovels.length) return null;
  return snap.shovels.find(s => s.shovel === wanted) || snap.shovels[0];
}

function drawArm(j) {
  if (!j || j.handle_deg == null || j.crowd_m == null) { $("joints").textContent = "arm: no data"; return; }
  const rad = Math.PI / 180, boom = (j.boom_deg ?? 45) * rad, th = j.handle_deg * rad;
  // Boom foot at the origin, point sheave 15 m up the boom, shipper shaft 7 m up (SVG y points down).
  const sx = 15 * Math.cos(boom), sy = -15 * Math.sin(boom);
  const px = 7 * Math.cos(boom), py = -7 * Math.sin(boom);
  const dx = px + j.crowd_m * Math.cos(th), dy = py - j.crowd_m * Math.sin(th);
  const set = (id, a) => { for (const k in a) $(id).setAttribute(k, a[k]); };
  set("boom", {x1: 0, y1: 0, x2: sx, y2: sy});
  set("handle", {x1: px, y1: py, x2: dx, y2: dy});
  set("rope", {x1: sx, y1: sy, x2: dx, y2: dy});
  set("dipper", {cx: dx, cy: dy});
  $("joints").textContent = `handle ${j.handle_deg.toFixed(0)}°  crowd ${j.crowd_m.toFixed(1)} m  swing ${(j.swing_deg ?? 0).toFixed(0)}°`;
}

function render(snap) {
  const s = pick(snap);
  const probs = screen.problems(snap, s);
  showProblems(probs, true);
  $("link").textContent = screen.socketUp && snap && snap.link === "up" ? "link up" : "link down";
  if (!s) return;
  $("shovel").textContent = s.shovel;
  const p = $("payload");
  const d = $("payload-doubt");
  if (s.valid && screen.socketUp) {
    // a crowd in doubt (its laser had a gap): the number in the warning's colour and a
    // line under it ("?" there: the number's own line has no room for it at 800 px);
    // the pass is weighed at the dump only if it fits the machine
    p.textContent = (s.payload_kg / 1000).toFixed(1) + " t";
    p.className = s.crowd_doubt ? "doubtful" : "";
    $("payload-std").textContent = s.std_kg == null ? "" : "± " + screen.t(s.std_kg);
    d.textContent = s.crowd_doubt ? `? crowd laser ${s.crowd_doubt}: checked at the dump` : "";
    d.title = d.textContent;
  } else {
    p.textContent = "no valid estimate";
    p.className = "invalid";
    $("payload-std").textContent = "";
    d.textContent = d.title = "";
  }
  $("phase").textContent = s.phase ? s.phase.toUpperCase() : "";
  const tr = s.truck || {};
  $("truck-no").textContent = tr.truck ?? "-";
  $("truck-passes").textContent = tr.passes ?? 0;
  $("truck-total").textContent = screen.load(tr);
  $("truck-target").textContent = screen.t(tr.target_kg, 0);
  $("remaining").textContent = s.remaining_kg == null ? "-" :
    (s.remaining_kg > 0 ? screen.t(s.remaining_kg) : "over by " + screen.t(-s.remaining_kg));
  const fill = tr.target_kg ? tr.total_kg / tr.target_kg : 0;
  const bar = $("gauge-fill");
  bar.style.width = Math.min(100, fill / 1.3 * 100).toFixed(1) + "%";
  bar.className = "fill" + (fill > 1.2 ? " alarm" : fill > 1.1 ? " warn" : "");
  $("hint").textContent = s.hint ? s.hint.text : "";
  const w = $("warning");
  w.textContent = s.warning ? s.warning.text : "";
  w.className = s.warning ? s.warning.level : "";
  $("passes").innerHTML = s.passes.map((q, i) => {
    if (!(q.pass in screen.shown)) screen.shown[q.pass] = Date.now();
    if (!q.valid) {
      // the reason's head on one line; a tap (the panel is touch) shows the whole for a while
      const whole = screen.tapped("pass" + q.pass);
      return `<tr class="invalid-pass" data-pass="${q.pass}"><td>${i + 1}</td><td colspan="2" class="reason${whole ? " whole" : ""}" title="${screen.esc(q.reason)}">not weighed: ${screen.esc(screen.clipped(q.reason || "", whole, 1))}</td></tr>`;
    }
    const doubt = q.misfit_high ? " ?" : "";
    return `<tr${doubt ? ' class="doubtful-pass"' : ""}><td>${i + 1}</td><td>${screen.tonnes(q.payload_kg)}${doubt}</td><td>${screen.tonnes(q.std_kg)}</td></tr>`;
  }).join("");
  $("doubt").textContent = s.doubt || "";
  $("trucks").innerHTML = s.closed.map(c =>
    `<tr><td>${c.truck}</td><td>${c.passes}</td><td>${c.invalid_passes ? "≥ " : ""}${screen.tonnes(c.total_kg)}</td><td>${c.fill_pct ?? "-"} %</td>${statusCell(c)}</tr>`).join("");
  $("shift").textContent = ruleLine(s.rule);
  drawArm(s.joints);
  screen.fitProblems(probs, showProblems, screen.tapped());
}

// A closed truck's status: "?" for one with a pass not weighed (its load is known only
// from below, "≥" in its tonnes), the whole in the cell's title; the panel has no room
// for more beside the fill.
function statusCell(c) {
  if (c.status !== "incomplete") return `<td>${screen.esc(c.status)}</td>`;
  const why = `${screen.n(c.invalid_passes, "pass", "passes")} not weighed: its load is not known`;
  return `<td class="not-weighed" title="${screen.esc(why)}">?</td>`;
}

// The 10/10/20 line: a truck with a pass not weighed is not judged (its load is known
// only from below), except over 120 % by its weighed passes alone: "4 of 5 trucks".
function ruleLine(r) {
  if (!r) return "no truck closed yet";
  const all = r.trucks + (r.not_judged || 0);
  if (!all) return "no truck closed yet";
  const verdict = r.compliant ? "within the 10/10/20 rule" : "OUTSIDE the 10/10/20 rule";
  if (!r.trucks) return `no truck judged of ${all}: a pass of each not weighed` + (r.over_120 ? `; ${r.over_120} over 120 % — ${verdict}` : "");
  return `${r.not_judged ? r.trucks + " of " + all + " trucks" : screen.n(r.trucks, "truck", "trucks")}, mean ${r.mean_pct ?? "-"} % of target, ${r.over_110_pct ?? "-"} % over 110 %, ${r.over_120 ?? 0} over 120 % — ${verdict}`;
}

function showProblems(probs, whole) {
  const h = $("health");
  h.textContent = probs.length ? probs.map(p => screen.clipped(p, whole)).join(" · ") : "all sensors ok";
  h.title = whole ? "" : probs.join("\n");
  h.className = probs.length ? "bad" : "ok";
}

screen.theme();
screen.tappable($("health"), () => "", () => render(screen.snapshot));
screen.tappable($("passes"), ev => {
  const row = ev.target.closest("tr.invalid-pass");
  return row ? "pass" + row.dataset.pass : null;
}, () => render(screen.snapshot));
screen.connect(render);
setInterval(() => render(screen.snapshot), 1000);
