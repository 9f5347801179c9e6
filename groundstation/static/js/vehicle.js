// The vehicle panel: the mission tree with each node's Fig. 5 status (seed 000 Sec. IV),
// pause (break-in) / resume / enough / abort / land (seed 000 Sec. VII), the joystick during a break-in, a
// live plot of altitude and speed, processes and in-flight gain tuning (seed 003 Sec. II, Process Monitor).
import { call } from "./api.js";
import { colour } from "./geo.js";
import { esc } from "./text.js";

const VERBS = ["pause", "resume", "enough", "user_confirm", "abort", "land", "take", "release", "start"];
const PLOT_S = 60;

function treeHtml(node) {
  if (!node) return "";
  const kids = node.children || [node.then, node.else].filter(Boolean);
  const prog = node.progress && node.progress.progress ? ` ${esc(node.progress.progress)}` : "";
  return `<li data-node="${esc(node.id)}">${esc(node.id)} <small>${esc(node.type)}</small>` +
    `<span class="state state-${esc(node.state)}">${esc(node.state)}</span>${prog}` +
    (kids.length ? `<ul>${kids.map(treeHtml).join("")}</ul>` : "") + "</li>";
}

export class VehiclePanel {
  constructor(el, ui) {
    this.el = el;
    this.ui = ui;  // {joystick, canCommand, applyRole, dialog}
    this.vid = null;
    this.series = new Map();  // vid -> [[t, alt, speed]]
    this.breakIn = false;
    this.treeTimer = null;
  }

  record(vehicles, now) {
    for (const v of vehicles) {
      if (!v.position) continue;
      let s = this.series.get(v.id);
      if (!s) { s = []; this.series.set(v.id, s); }
      const sp = v.velocity ? Math.hypot(v.velocity[0], v.velocity[1]) : 0;
      s.push([now, v.position.alt, sp]);
      while (s.length && now - s[0][0] > PLOT_S) s.shift();
    }
  }

  select(vid) {
    if (this.vid === vid) return;
    this.vid = vid;
    this.breakIn = false;
    this.lastState = null;
    this.ui.joystick.engage(null);
    this.el.innerHTML = `<h3>vehicle ${esc(vid)} <span class="vname"></span> <span class="vstate"></span></h3>
      <div class="buttons">${VERBS.map((v) => `<button type="button" data-cmd data-verb="${v}">${v === "pause" ?
        "pause (break in)" : v === "user_confirm" ? "confirm" : v}</button>`).join("")}</div>
      <div class="result hint"></div>
      <div class="joystick" hidden><b>Break-in joystick</b> — arrows/WASD move, Q/E yaw, R/F up/down, or a gamepad.
        <div class="jrow"><div class="pad"><div class="knob"></div></div>
        <label>speed <input class="jspeed" type="range" min="0.5" max="5" step="0.5" value="2"></label>
        <span class="jout"></span></div>
        <div><span class="jlease"></span> <button type="button" class="jtake" data-cmd>take the stick</button>
        <button type="button" class="jrelease" data-cmd>release the stick</button></div></div>
      <canvas class="plot" width="440" height="90"></canvas>
      <div class="tree"><ul></ul></div>
      <details class="procs"><summary>Processes</summary><div class="plist"></div></details>
      <details class="params"><summary>Parameters (in-flight tuning, guarded)</summary>
        <input class="pname" value="ATC_RAT_RLL_P" aria-label="parameter name" maxlength="16">
        <button type="button" class="pget">read</button> <span class="prange hint"></span><br>
        <input class="pval" type="number" step="any" aria-label="new value" placeholder="new value">
        <label title="operator only: accept more than a 50 % change while the vehicle flies"><input type="checkbox"
          class="pforce" data-cmd> force</label>
        <button type="button" class="pset" data-cmd>set…</button>
        <div class="pout"></div></details>`;
    this.el.querySelector("h3").style.color = colour(vid);
    for (const b of this.el.querySelectorAll("[data-verb]")) b.addEventListener("click", () => this.command(b.dataset.verb));
    this.ui.joystick.bindPad(this.el.querySelector(".pad"));
    this.el.querySelector(".jtake").addEventListener("click", () => this.ui.joystick.engage(this.vid));
    this.el.querySelector(".jrelease").addEventListener("click", () => this.ui.joystick.engage(null));
    this.el.querySelector(".jspeed").addEventListener("input", (e) => { this.ui.joystick.speed = Number(e.target.value); });
    this.el.querySelector(".procs").addEventListener("toggle", () => this.processes());
    this.el.querySelector(".pget").addEventListener("click", () => this.readParam());
    this.el.querySelector(".pset").addEventListener("click", () => this.setParam());
    this.el.querySelector(".params").addEventListener("toggle", (e) => { if (e.target.open) this.readParam(); });
    this.ui.applyRole();
    clearInterval(this.treeTimer);
    this.treeTimer = setInterval(() => this.tree(), 1000);
    this.tree();
  }

  async command(verb) {
    const out = this.el.querySelector(".result");
    const vid = this.vid;
    out.textContent = `${verb}…`;
    const r = await call("POST", `/api/vehicles/${vid}/${verb}`);
    out.textContent = r.status === 200 ? `${verb}: ok` : `${verb}: ${r.status} ${r.body?.error || ""}`;
    out.dataset.last = `${verb}:${r.status}`;
    if (vid !== this.vid) return;
    if (verb === "pause" && r.status === 200) this.setBreakIn(true);
    if (["resume", "abort", "land", "enough"].includes(verb) && r.status === 200) this.setBreakIn(false);
    this.tree();
  }

  /** The joystick panel shown (paused); ``fly``: this page takes the stick lease and streams. */
  setBreakIn(on, fly = on) {
    this.breakIn = on;
    this.el.querySelector(".joystick").hidden = !on;
    if (fly || !on) this.ui.joystick.engage(fly ? this.vid : null);
  }

  /** Who holds the stick (``v.stick_lease`` of the snapshot), shown on every page. */
  showLease(v) {
    const j = this.ui.joystick, mine = j.holds(v.id), lease = v.stick_lease;
    const text = mine ? "stick: this page flies it" : lease ? `stick held by ${lease.holder} (lease lapses ` +
      `${Number(lease.expires_in).toFixed(1)} s after its last sample)` : `stick free${j.status ? ": " + j.status : ""}`;
    const el = this.el.querySelector(".jlease");
    if (el.textContent !== text) el.textContent = text;
    el.dataset.holder = mine ? "me" : lease ? lease.holder : "";
    this.el.querySelector(".jtake").hidden = mine || !!lease || !this.ui.canCommand();
    this.el.querySelector(".jrelease").hidden = !mine;
  }

  async tree() {
    if (this.vid == null) return;
    const vid = this.vid;
    const r = await call("GET", `/api/vehicles/${vid}/mission`);
    if (vid !== this.vid) return;
    const ul = this.el.querySelector(".tree ul");
    if (r.status !== 200) { ul.innerHTML = `<li class="hint">no mission (${esc(r.body?.error || r.status)})</li>`; return; }
    const html = r.body.tree ? treeHtml(r.body.tree) : `<li class="hint">no mission</li>`;
    if (ul.innerHTML !== html) ul.innerHTML = html;
    this.el.querySelector(".tree").dataset.state = r.body.state || "none";
  }

  async processes() {
    const r = await call("GET", `/api/vehicles/${this.vid}/processes`);
    const div = this.el.querySelector(".plist");
    div.innerHTML = r.status === 200 ? `<ul>${r.body.map((p) => `<li>${esc(p.name)}: ${esc(p.status ?? p.state ?? "")}
      </li>`).join("")}</ul>` : esc(r.body?.error || r.status);
  }

  /** The parameter's value now and its range (the vehicle's table, as its companion reports it). */
  async readParam() {
    const name = this.el.querySelector(".pname").value.trim().toUpperCase();
    const range = this.el.querySelector(".prange");
    const r = await call("GET", `/api/vehicles/${this.vid}/params/${encodeURIComponent(name)}`);
    if (r.status !== 200) { range.textContent = `${name}: ${r.status} ${r.body?.error || ""}`; return null; }
    const p = r.body;
    const box = this.el.querySelector(".pval");
    box.placeholder = `now ${p.value}`;
    if (p.min != null) { box.min = p.min; box.max = p.max; }
    range.textContent = `${p.name} = ${p.value}` + (p.min != null
      ? ` · range [${p.min}, ${p.max}]${p.units ? " " + p.units : ""} · ${p.description || ""} (${p.autopilot})`
      : " · not in the table of tunable parameters: it cannot be set here");
    range.dataset.min = p.min ?? "";
    range.dataset.max = p.max ?? "";
    return p;
  }

  /** A guarded write: a number (never an empty box read as 0), inside the range, confirmed in a dialog that
   *  shows the old and the new value; the answer is the autopilot's read-back. */
  async setParam() {
    const name = this.el.querySelector(".pname").value.trim().toUpperCase();
    const box = this.el.querySelector(".pval");
    const out = this.el.querySelector(".pout");
    const force = this.el.querySelector(".pforce").checked;
    const raw = box.value.trim();
    const refuse = (why) => { out.textContent = `not sent: ${why}`; out.dataset.last = "refused"; };
    if (raw === "" || box.validity.badInput) return refuse("enter a number (the value box is empty or not a number)");
    const value = Number(raw);
    if (!Number.isFinite(value)) return refuse(`${raw} is not a number`);
    const vid = this.vid;
    const p = await this.readParam();
    if (!p) return refuse("the current value could not be read");
    if (p.min == null) return refuse(`${name} is not in the table of tunable parameters`);
    if (value < p.min || value > p.max) return refuse(`${value} is out of range [${p.min}, ${p.max}]`);
    const units = p.units ? ` ${esc(p.units)}` : "";
    const ans = await this.ui.dialog(`Set ${name} on vehicle ${vid}?`,
      `<p class="pconfirm"><b>${esc(name)}</b>: <span class="old">${esc(p.value)}</span> → <span class="new">${esc(value)}</span>${units}</p>
       <p class="hint">range [${esc(p.min)}, ${esc(p.max)}]${units} · ${esc(p.description || "")}</p>` +
       (force ? "<p><b>forced</b>: no in-flight bound on the change</p>" : ""),
      [["set", `Set ${name} = ${value}`], ["", "Cancel"]]);
    if (ans !== "set" || vid !== this.vid) { out.textContent = "cancelled: nothing sent"; out.dataset.last = "cancelled"; return; }
    const r = await call("PUT", `/api/vehicles/${vid}/params/${encodeURIComponent(name)}`, { value, force });
    out.textContent = r.status === 200 ? `${r.body.name}: ${r.body.old} → ${r.body.value} (read back from the autopilot)`
      : `refused (${r.status}): ${r.body?.error || ""}`;
    out.dataset.last = r.status === 200 ? "set" : `refused:${r.status}`;
    if (r.status === 200) { box.value = ""; this.readParam(); }
  }

  /** Each snapshot: state line, joystick read-out, plot. */
  update(v) {
    if (!v || v.id !== this.vid) return;
    const m = v.mission || {};
    const vn = this.el.querySelector(".vname");
    if (vn.textContent !== (v.name || "")) vn.textContent = v.name || "";
    const st = this.el.querySelector(".vstate");
    const text = `${v.mode || ""} · ${m.state || "no mission"}${m.node ? " · " + m.node : ""}${v.alert ? " · ⚠ " + v.alert : ""}`;
    if (st.textContent !== text) st.textContent = text;
    // a break-in begun elsewhere (another operator's page): shown paused with who holds the stick, nothing
    // sent (the stick is taken explicitly), on the change to paused only (a snapshot older than our own
    // resume still says paused)
    if (m.state === "paused" && this.lastState !== "paused" && !this.breakIn) this.setBreakIn(true, false);
    if (this.breakIn && m.state && m.state !== "paused" && this.lastState === "paused") this.setBreakIn(false);
    this.showLease(v);
    this.lastState = m.state;
    if (this.breakIn) {
      const j = this.ui.joystick;
      this.el.querySelector(".jout").textContent = `[${j.last.map((x) => x.toFixed(1)).join(", ")}] · ${j.sent} sent`;
    }
    this.plot();
  }

  plot() {
    const c = this.el.querySelector("canvas.plot");
    const s = this.series.get(this.vid) || [];
    const g = c.getContext("2d");
    g.clearRect(0, 0, c.width, c.height);
    if (s.length < 2) return;
    const t1 = s[s.length - 1][0];
    const x = (t) => c.width - ((t1 - t) / PLOT_S) * c.width;
    const line = (k, max, col, label) => {
      g.strokeStyle = col; g.beginPath();
      s.forEach((p, i) => { const y = c.height - 4 - (p[k] / max) * (c.height - 14); if (i) g.lineTo(x(p[0]), y); else g.moveTo(x(p[0]), y); });
      g.stroke(); g.fillStyle = col; g.fillText(label, k === 1 ? 4 : 140, 10);
    };
    const amax = Math.max(5, ...s.map((p) => p[1]));
    const vmax = Math.max(2, ...s.map((p) => p[2]));
    line(1, amax, "#2760c4", `alt ${s[s.length - 1][1].toFixed(1)} m (max ${amax.toFixed(0)})`);
    line(2, vmax, "#c42727", `speed ${s[s.length - 1][2].toFixed(1)} m/s`);
  }
}
