// The fleet list, task list and alerts (seed 003 Sec. II: "A list of the fleet
// members displays each UAV's map icon, current task, and most recent communication. The task list displays
// the list of assigned tasks, any of which can be canceled at any time.").
import { colour } from "./geo.js";
import { esc } from "./text.js";

const ALERT_KINDS = new Set(["failsafe", "override", "link_lost", "confirmation_required", "detection"]);

function cell(tr, n) { return tr.children[n]; }

function set(el, text) { if (el.textContent !== text) el.textContent = text; }

export class FleetList {
  constructor(tbody, onPick) {
    this.tbody = tbody;
    this.onPick = onPick;
    this.rows = new Map();
    this.selected = null;
  }

  ticked() { return [...this.rows.entries()].filter(([, tr]) => tr.querySelector("input").checked).map(([id]) => id); }

  update(vehicles) {
    for (const v of vehicles) {
      let tr = this.rows.get(v.id);
      if (!tr) {
        tr = document.createElement("tr");
        tr.dataset.vehicle = v.id;
        tr.innerHTML = `<td><input type="checkbox" title="tick for a command to several vehicles"></td>
          <td><span class="swatch"></span> <span class="dot"></span></td>
          <td></td><td></td><td></td><td></td><td></td><td></td>`;
        tr.querySelector(".swatch").style.background = colour(v.id);
        tr.addEventListener("click", (ev) => { if (ev.target.tagName !== "INPUT") this.onPick(v.id); });
        const after = [...this.rows.keys()].filter((id) => id > v.id).sort((a, b) => a - b)[0];
        this.tbody.insertBefore(tr, after ? this.rows.get(after) : null);
        this.rows.set(v.id, tr);
      }
      tr.classList.toggle("selected", v.id === this.selected);
      const dot = cell(tr, 1).querySelector(".dot");
      dot.className = `dot health-${v.health.level}`;
      dot.title = v.health.reasons.join("; ") || "healthy";
      set(cell(tr, 2), (v.name || `vehicle ${v.id}`) + (v.alert ? " ⚠" : ""));
      set(cell(tr, 3), v.task != null ? `task ${v.task}` : (v.member_status || v.team_state));
      const m = v.mission || {};
      set(cell(tr, 4), m.node ? `${m.node} ${m.progress || ""}`.trim() : (m.state && m.state !== "none" ? m.state : ""));
      set(cell(tr, 5), v.battery != null ? `${Math.round(v.battery)}%` : "");
      set(cell(tr, 6), `${v.mode || "?"}${v.armed ? "" : " (disarmed)"}`);
      set(cell(tr, 7), v.age_s != null ? `${v.age_s.toFixed(1)} s` : "");
    }
  }
}

export class TaskList {
  constructor(tbody, onCancel) {
    this.tbody = tbody;
    this.onCancel = onCancel;
    this.rows = new Map();
  }

  update(tasks) {
    for (const t of tasks) {
      let tr = this.rows.get(t.id);
      if (!tr) {
        tr = document.createElement("tr");
        tr.dataset.task = t.id;
        tr.innerHTML = `<td>${esc(t.id)}</td><td></td><td class="state"></td><td class="holder"></td><td></td>
          <td><button type="button" class="cancel" data-cmd>Cancel</button></td>`;
        tr.querySelector("button").addEventListener("click", () => this.onCancel(t));
        this.tbody.prepend(tr);
        this.rows.set(t.id, tr);
      }
      set(cell(tr, 1), `${t.kind}${t.group ? " (group " + t.group + ")" : ""}${t.name ? " " + t.name : ""}`);
      set(cell(tr, 2), t.state);
      const holder = cell(tr, 3);
      if (holder.dataset.holder !== String(t.holder ?? "")) {  // a swatch and the holder's id, as text
        holder.dataset.holder = String(t.holder ?? "");
        holder.textContent = t.holder ? ` ${t.holder}` : "—";
        if (t.holder) { const sw = document.createElement("span"); sw.className = "swatch"; sw.style.background = colour(t.holder); holder.prepend(sw); }
      }
      set(cell(tr, 4), t.cost != null ? `${t.cost.toFixed(0)} s` : "");
      tr.querySelector("button").hidden = t.state === "done" || t.state === "cancelled";
    }
  }
}

export class Alerts {
  constructor(ul, countEl) {
    this.ul = ul;
    this.countEl = countEl;
    this.n = 0;
    this.byVehicle = new Map();  // vid -> {text, until}
  }

  /** An event from the service; alerts kinds go to the list and onto the vehicle for 30 s. */
  add(ev) {
    if (!ALERT_KINDS.has(ev.kind)) return false;
    const li = document.createElement("li");
    li.className = ev.severity;
    li.dataset.kind = ev.kind;
    li.textContent = `${new Date(ev.t * 1000).toLocaleTimeString()} ${ev.kind}: ${ev.message}`;
    this.ul.prepend(li);
    while (this.ul.children.length > 200) this.ul.lastChild.remove();
    this.n += 1;
    this.countEl.textContent = `(${this.n})`;
    if (ev.vehicle != null) this.byVehicle.set(ev.vehicle, { text: ev.kind.replace("_", " "), until: Date.now() + 30000 });
    return true;
  }

  /** The vehicle's live alert (or null). */
  of(vid) {
    const a = this.byVehicle.get(vid);
    return a && a.until > Date.now() ? a.text : null;
  }
}
