// The operator's fence drawn on the map and sent to the vehicles: POST /api/fence makes it the service's
// operational fence (tasks outside it refused) and each companion uploads it to its autopilot's fence
// (the MAVLink mission protocol, MAV_MISSION_TYPE_FENCE, as ArduCopter stores a polygon) and enables it.
import { call } from "./api.js";
import { esc } from "./text.js";

/** Wires the fence button. ``ui``: {dialog, hint(text), vehicles() -> Map, map (FleetMap), canCommand()}. */
export function fenceDraw(ui) {
  const $ = (id) => document.getElementById(id);
  const button = document.querySelector("[data-fence]");
  if (!button) return null;

  function done() {
    button.classList.remove("on");
    $("draw-finish").hidden = true;
    $("draw-cancel").hidden = true;
  }

  async function send(points) {
    done();
    const all = [...ui.vehicles().values()];
    const list = all.map((v) => `<li>${esc(v.name || "vehicle " + v.id)} (${esc(v.id)})</li>`).join("");
    const ans = await ui.dialog(`Send a fence of ${points.length} vertices?`, `<p>The polygon becomes the
      operational fence, and every vehicle's autopilot stores and enables it (a vehicle outside it breaches
      it):</p><ul class="targets">${list}</ul>`, [["yes", `Send to ${all.length} vehicles`], ["", "Cancel"]]);
    if (ans !== "yes") { ui.hint("fence: not sent"); return; }
    const r = await call("POST", "/api/fence", { points });
    const out = $("verb-result");
    if (r.status !== 200) { ui.hint(`fence refused: ${r.body?.error || r.status}`); return; }
    ui.map.setFence(r.body.points);
    const text = r.body.results.map((x) => `${x.vehicle}: ${x.ok ? `${x.answer.vertices} vertices${x.answer.enabled
      ? ", enabled" : ""}` : x.error}`).join("; ");
    ui.hint(`fence: ${text}`);
    if (out) { out.dataset.verb = "fence"; out.textContent = `Fence: ${text}`; }
  }

  button.addEventListener("click", () => {
    if (!ui.canCommand()) return;
    for (const b of document.querySelectorAll("[data-draw]")) b.classList.remove("on");
    button.classList.add("on");
    $("draw-finish").hidden = false;
    $("draw-cancel").hidden = false;
    $("draw-cancel").addEventListener("click", done, { once: true });
    ui.hint("click the fence's corners, then Finish (or double-click)");
    ui.map.startDraw("fence", send);
  });
  return { send };
}
