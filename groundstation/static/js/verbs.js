// The verbs an operator reaches for (QGroundControl's and Mission Planner's "RTL", "land all", "pause"):
// return one vehicle or the whole fleet home, land them all, hold them all where they are (button or the
// H key); each asks for a confirmation naming its targets, and shows every vehicle's answer. Cancelling one
// piece of a divided task asks whether the whole group goes (seed 003 Sec. II: the operator cancels tasks).
import { call } from "./api.js";
import { esc } from "./text.js";

const VERBS = {
  rtl_all: { path: "/api/fleet/rtl", title: "Return all home", what: "return home and land (RTL)",
    button: "Return all home" },
  land_all: { path: "/api/fleet/land", title: "Land all", what: "land where it is", button: "Land all" },
  hold_all: { path: "/api/fleet/hold", title: "Hold all", what: "pause its mission and hold in place",
    button: "Hold all" },
};

/** Each vehicle's answer, as plain text (shown with textContent). */
export function answers(r) {
  if (r.status !== 200) return `refused: ${r.body?.error || r.status}`;
  return r.body.results.map((x) => `${x.vehicle}: ${x.ok ? "ok" : x.error}`).join("; ");
}

/** Wires the fleet verbs. ``ui``: {dialog, hint(text), vehicles() -> Map, selected() -> vid|null,
 * canCommand()}. */
export function setupVerbs(ui) {
  const $ = (id) => document.getElementById(id);

  async function fleetVerb(key) {
    if (!ui.canCommand()) return;
    const v = VERBS[key];
    const all = [...ui.vehicles().values()];
    const list = all.map((x) => `<li>${esc(x.name || "vehicle " + x.id)} (${esc(x.id)})</li>`).join("");
    const ans = await ui.dialog(`${v.title}?`, `<p>Every vehicle of the fleet will ${esc(v.what)}:</p>
      <ul class="targets">${list}</ul>`, [["yes", `${v.button} (${all.length})`], ["", "Cancel"]]);
    if (ans !== "yes") { ui.hint(`${v.title}: not sent`); return; }
    const r = await call("POST", v.path);
    ui.hint(`${v.title}: ${answers(r)}`);
    const out = $("verb-result");
    if (out) { out.dataset.verb = key; out.textContent = `${v.title}: ${answers(r)}`; }
  }

  async function rtlOne() {
    const vid = ui.selected();
    if (!ui.canCommand()) return;
    if (vid == null) { ui.hint("RTL: click a vehicle first"); return; }
    const v = ui.vehicles().get(vid);
    const ans = await ui.dialog(`Return ${v?.name || "vehicle " + vid} home?`,
      `<p>Vehicle ${esc(vid)} will return home and land (RTL).</p>`, [["yes", "RTL"], ["", "Cancel"]]);
    if (ans !== "yes") return;
    const r = await call("POST", `/api/vehicles/${vid}/rtl`);
    ui.hint(r.status === 200 ? `vehicle ${vid}: RTL` : `RTL refused: ${r.body?.error || r.status}`);
  }

  for (const key of Object.keys(VERBS)) {
    const b = document.querySelector(`[data-verb='${key}']`);
    if (b) b.addEventListener("click", () => fleetVerb(key));
  }
  const one = document.querySelector("[data-verb='rtl_one']");
  if (one) one.addEventListener("click", rtlOne);
  window.addEventListener("keydown", (e) => {  // H: hold all (never while typing)
    const t = e.target;
    if (e.code !== "KeyH" || e.repeat || e.ctrlKey || e.metaKey || e.altKey) return;
    if (t && (t.tagName === "INPUT" || t.tagName === "SELECT" || t.tagName === "TEXTAREA")) return;
    if (document.querySelector("dialog[open]:modal")) return;
    e.preventDefault();
    fleetVerb("hold_all");
  });
  return { fleetVerb, rtlOne };
}

/** Cancel task ``t``: a piece of a divided task asks whether the whole group goes. */
export async function cancelTaskAsking(t, tasksById, dialog, hint) {
  const pieces = t.group ? [...tasksById.values()].filter((x) => x.group === t.group && x.state !== "cancelled"
    && x.state !== "done") : [];
  let target = t.id;
  if (pieces.length > 1) {
    const ids = pieces.map((x) => x.id).join(", ");
    const ans = await dialog(`Cancel task ${t.id}?`, `<p>Task ${esc(t.id)} is one of ${pieces.length} pieces of
      the divided ${esc(t.kind)} (group ${esc(t.group)}: tasks ${esc(ids)}).</p>`,
    [["one", `Only task ${t.id}`], ["group", `The whole group (${pieces.length})`], ["", "Keep it"]]);
    if (!ans) return;
    target = ans === "group" ? t.group : t.id;
  }
  const r = await call("DELETE", `/api/tasks/${target}`);
  hint(r.status === 200 ? `cancelled ${r.body.cancelled.join(", ")}` : `refused: ${r.body?.error}`);
}
