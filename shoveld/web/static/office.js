// The mine office page: one card per shovel on the Zenoh network.
"use strict";
function card(s, whole) {
  const tr = s.truck || {};
  const state = s.silent ? `<span class="silent-tag">SILENT${s.age_s != null ? " for " + s.age_s.toFixed(0) + " s" : ""}</span>`
    : `<span class="state">${screen.esc((s.phase || "idle").toUpperCase())}</span>`;
  const live = s.valid ? screen.t(s.payload_kg) + (s.std_kg == null ? "" : " ± " + screen.t(s.std_kg)) : "no valid estimate";
  const doubt = s.crowd_doubt ? ` <span class="doubtful" title="the crowd laser ${screen.esc(s.crowd_doubt)}">? crowd laser in doubt</span>` : "";
  return `<section class="panel card${s.silent ? " silent" : ""}" data-shovel="${screen.esc(s.shovel)}">
    <h2>${screen.esc(s.shovel)} ${state}</h2>
    <div>live payload: <b class="live">${live}</b>${doubt}</div>
    <div>truck ${tr.truck ?? "-"}: <b class="truck">${screen.load(tr)}</b> of ${screen.t(tr.target_kg, 0)}, ${screen.n(tr.passes ?? 0, "pass", "passes")}${tr.invalid_passes ? `, <span class="doubtful not-weighed">${tr.invalid_passes} not weighed</span>` : ""}</div>
    <div>this shift: <b class="shift">${screen.n(s.shift.passes, "pass", "passes")}, ${s.shift.not_weighed ? "≥ " : ""}${screen.t(s.shift.kg)}</b> in ${screen.n(s.shift.trucks, "truck", "trucks")}${s.shift.not_weighed ? `; <span class="doubtful not-weighed">${s.shift.not_weighed} not weighed</span>` : ""}${s.shift.misfit_high ? `; <span class="doubtful">${screen.n(s.shift.misfit_high, "pass", "passes")} the model did not fit</span>` : ""}</div>
    <div class="problems">${s.problems.map(p => `<div title="${screen.esc(p)}">${screen.esc(screen.clipped(p, whole))}</div>`).join("")}</div>
  </section>`;
}
function render(snap) {
  const probs = screen.problems(snap, null);
  const h = document.getElementById("health");
  h.textContent = probs.length ? probs.join(" · ") : "link ok";
  h.className = probs.length ? "bad" : "ok";
  if (!snap) return;
  const cards = document.getElementById("cards");
  screen.fitProblems(snap.shovels.flatMap(s => s.problems), (_, whole) => {
    cards.innerHTML = snap.shovels.map(s => card(s, whole || screen.tapped(s.shovel))).join("");
  });
  const silent = snap.shovels.filter(s => s.silent).length;
  document.getElementById("summary").textContent = `${screen.n(snap.shovels.length, "shovel", "shovels")}, ${silent} silent`;
  document.getElementById("link").textContent = snap.link === "up" ? "link up" : "link down";
}
screen.theme();
// a tap on a card's problems shows that card's whole (the cards are drawn anew each second)
screen.tappable(document.getElementById("cards"), ev => {
  const c = ev.target.closest(".problems") && ev.target.closest(".card");
  return c ? c.dataset.shovel : null;
}, () => render(screen.snapshot));
screen.connect(render);
setInterval(() => render(screen.snapshot), 1000);
