// The fleet list, task list and alerts (seed 003 Sec. II: "A list of the fleet
// members displays each UAV's map icon, current task, and most recent communication. The task list displays
// the list of assigned tasks, any of which can be canceled at any time.").
import { colour } from "./geo.js";
import { esc } from "./text.js";

// the service's alert kinds (GET /api/alerts names them; this is the set until it answered)
let ALERT_KINDS = new Set(["failsafe", "override", "link_lost", "battery_low", "battery_critical", "duplicate_id",
  "confirmation_required", "detection", "conflict"]);

/** "live", "stale" or "lost": how long ago the vehicle was heard, against the service's stale / lost times. */
export function linkOf(v, staleS = 2, lostS = 5) {
  if (v.age_s == null) return "live";
  return v.age_s > lostS ? "lost" : v.age_s > staleS ? "stale" : "live";
}

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
      const link = v.link || "live";
      tr.classList.toggle("stale", link === "stale");
      tr.classList.toggle("lost", link === "lost");
      tr.dataset.link = link;
      const dot = cell(tr, 1).querySelector(".dot");
      dot.className = `dot health-${v.health.level}`;
      dot.title = v.health.reasons.join("; ") || "healthy";
      set(cell(tr, 2), (v.name || `vehicle ${v.id}`) + (v.alert ? " ⚠" : ""));
      set(cell(tr, 3), v.task != null ? `task ${v.task}` : (v.member_status || v.team_state));
      const m = v.mission || {};
      set(cell(tr, 4), m.node ? `${m.node} ${m.progress || ""}`.trim() : (m.state && m.state !== "none" ? m.state : ""));
      set(cell(tr, 5), v.battery != null ? `${Math.round(v.battery)}%` : "");
      set(cell(tr, 6), `${v.mode || "?"}${v.armed ? "" : " (disarmed)"}`);
      const age = v.age_s != null ? `${v.age_s.toFixed(1)} s` : "";
      set(cell(tr, 7), link === "lost" ? `lost ${age}` : link === "stale" ? `stale ${age}` : age);
    }
  }
}

export class TaskList {
  constructor(tbody, onCancel, onRelease) {
    this.tbody = tbody;
    this.onCancel = onCancel;
    this.onRelease = onRelease;
    this.rows = new Map();
  }

  update(tasks) {
    for (const t of tasks) {
      let tr = this.rows.get(t.id);
      if (!tr) {
        tr = document.createElement("tr");
        tr.dataset.task = t.id;
        tr.innerHTML = `<td>${esc(t.id)}</td><td></td><td class="state"></td><td class="holder"></td><td></td>
          <td><button type="button" class="release" data-cmd hidden title="give this task of an earlier run to the team">Release</button>
          <button type="button" class="cancel" data-cmd>Cancel</button></td>`;
        tr.querySelector("button.cancel").addEventListener("click", () => this.onCancel(t));
        tr.querySelector("button.release").addEventListener("click", () => this.onRelease([t.id]));
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
      tr.querySelector("button.cancel").hidden = t.state === "done" || t.state === "cancelled";
      tr.querySelector("button.release").hidden = t.state !== "held";
      tr.classList.toggle("held", t.state === "held");
    }
  }
}

export class Alerts {
  constructor(ul, countEl, onAck) {
    this.ul = ul;
    this.countEl = countEl;
    this.onAck = onAck;
    this.items = new Map();  // event id -> li
    this.byVehicle = new Map();  // vid -> {text, until}
  }

  /** The service's alert history (GET /api/alerts, oldest first), loaded on every (re)connect: the list is
   * rebuilt from it, so nothing is lost by a reload and nothing is shown twice. */
  load(rows, kinds) {
    if (kinds) ALERT_KINDS = new Set(kinds);
    this.ul.textContent = "";
    this.items.clear();
    for (const ev of rows) this.add(ev, false);
  }

  /** An event from the service; alerts kinds go to the list and onto the vehicle for 30 s. */
  add(ev, live = true) {
    if (!ALERT_KINDS.has(ev.kind)) return false;
    if (ev.id && this.items.has(ev.id)) return false;
    const li = document.createElement("li");
    li.className = ev.severity;
    li.dataset.kind = ev.kind;
    if (ev.id) li.dataset.event = ev.id;
    const text = document.createElement("span");
    text.textContent = `${new Date(ev.t * 1000).toLocaleTimeString()} ${ev.kind}: ${ev.message}`;
    const ack = document.createElement("button");
    ack.type = "button";
    ack.className = "ack";
    ack.dataset.cmd = "";
    ack.textContent = "Ack";
    ack.title = "acknowledge (every operator sees it acknowledged)";
    ack.addEventListener("click", () => this.onAck(ev.id));
    const by = document.createElement("span");
    by.className = "acked-by";
    li.append(text, " ", ack, by);
    this.ul.prepend(li);
    if (ev.id) this.items.set(ev.id, li);
    this.acked(ev.id, ev.acked_by, ev.acked_at);
    while (this.ul.children.length > 200) {
      const last = this.ul.lastChild;
      this.items.delete(Number(last.dataset.event));
      last.remove();
    }
    this.count();
    if (live && ev.vehicle != null) this.byVehicle.set(ev.vehicle, { text: ev.kind.replace("_", " "), until: Date.now() + 30000 });
    return true;
  }

  /** Alert ``id`` acknowledged by ``by`` (an ``ack`` message, or the history). */
  acked(id, by, at) {
    const li = this.items.get(id);
    if (!li) return;
    const done = by != null;
    li.classList.toggle("acked", done);
    li.querySelector("button.ack").hidden = done || !id;
    li.querySelector(".acked-by").textContent = done ? ` acknowledged by ${by}${at ? " " + new Date(at * 1000).toLocaleTimeString() : ""}` : "";
    this.count();
  }

  count() {
    const open = this.ul.querySelectorAll("li:not(.acked)").length;
    this.countEl.textContent = `(${open} open / ${this.ul.children.length})`;
  }

  /** The vehicle's live alert (or null). */
  of(vid) {
    const a = this.byVehicle.get(vid);
    return a && a.until > Date.now() ? a.text : null;
  }
}
