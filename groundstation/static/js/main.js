// The operator's web UI (seed 003 Sec. II, the Team Control interface): login, the live stream,
// the map, the lists, the vehicle panel and the dialogs. Snapshots arrive at 10 Hz; the latest is drawn
// in the next animation frame (stats in window.taskflight.stats for the bench and the tests).
import { call, Live, setToken, token } from "./api.js";
import { fenceDraw } from "./fence_draw.js";
import { getHome, setHome, toLocal } from "./geo.js";
import { Joystick } from "./joystick.js";
import { Alerts, FleetList, TaskList } from "./lists.js";
import { FleetMap } from "./map.js";
import { setupMissionUpload } from "./mission_upload.js";
import { VehiclePanel } from "./vehicle.js";
import { cancelTaskAsking, setupVerbs } from "./verbs.js";

const $ = (id) => document.getElementById(id);
const stats = { snapshots: 0, renders: 0, renderTimes: [], frameTimes: [], intervals: [], lastRender: 0, lastFrame: 0, seq: 0 };
let role = null, live = null, fmap = null, fleet = null, tasks = null, alerts = null, panel = null, joystick = null;
let pending = null, vehiclesById = new Map(), tasksById = new Map();
let fencePoints = null, fenceDrawn = false;

/** A modal dialog; resolves to the value of the button pressed. */
function dialog(title, bodyHtml, buttons) {
  const d = $("dialog");
  $("dialog-title").textContent = title;
  $("dialog-body").innerHTML = bodyHtml;
  $("dialog-buttons").innerHTML = buttons.map(([v, label]) => `<button value="${v}" data-answer="${v}">${label}</button>`).join("");
  return new Promise((resolve) => {
    d.addEventListener("close", () => resolve(d.returnValue), { once: true });
    d.returnValue = "";
    d.showModal();
  });
}

const canCommand = () => role === "operator";

/** An observer sees everything and commands nothing: every command button disabled, saying why. */
function applyRole() {
  for (const b of document.querySelectorAll("[data-cmd]")) {
    b.disabled = !canCommand();
    b.title = canCommand() ? "" : `disabled: the ${role} role may not command (log in with an operator token)`;
  }
}

function pick(vid) {
  fleet.selected = vid;
  panel.select(vid);
}

async function addTask(type, points) {
  const alt = Number($("task-alt").value) || 0;
  const body = { type, altitude: alt };
  if (type === "visit") body.point = [...points[0], alt];
  else if (type === "area_scan") body.area = points;
  else body.points = points.map((p) => [...p, alt]);
  if (type === "border_patrol" || type === "area_scan") body.vehicles = Math.max(1, Number($("task-n").value) || 1);
  let r = await call("POST", "/api/tasks", body);
  if (r.status === 409 && r.body && r.body.offer != null) {
    const ans = await dialog("Fewer vehicles free", `<p>${body.vehicles} vehicles asked for; ${r.body.free} free.
      The service offers N = <b class="offer">${r.body.offer}</b>.</p>`,
    [["accept", `Accept N = ${r.body.offer}`], ["force", `Keep N = ${body.vehicles} (pieces wait)`], ["", "Cancel"]]);
    if (!ans) return;
    r = await call("POST", "/api/tasks", ans === "accept" ? { ...body, vehicles: r.body.offer } : { ...body, force: true });
  }
  $("draw-hint").textContent = r.status === 201 ? `added task ${r.body.ids.join(", ")}` : `refused: ${r.body?.error}`;
}

function startDraw(type) {
  for (const b of document.querySelectorAll("[data-draw]")) b.classList.toggle("on", b.dataset.draw === type);
  const hint = { visit: "click the point to visit", patrol_line: "click the line's points, then Finish (or double-click)",
    border_patrol: "click the border's points, then Finish", area_scan: "click the polygon's corners, then Finish" }[type];
  $("draw-hint").textContent = hint;
  $("draw-finish").hidden = type === "visit";
  $("draw-cancel").hidden = false;
  fmap.startDraw(type, (pts) => { endDraw(); addTask(type, pts); });
}

function endDraw() {
  for (const b of document.querySelectorAll("[data-draw]")) b.classList.remove("on");
  $("draw-finish").hidden = true;
  $("draw-cancel").hidden = true;
}

function cancelTask(t) {  // a piece of a divided task asks whether the whole group goes (verbs.js)
  return cancelTaskAsking(t, tasksById, dialog, (text) => { $("draw-hint").textContent = text; });
}

async function commandMany() {
  const ids = fleet.ticked();
  const verb = $("multi-cmd").value;
  if (!ids.length) { $("draw-hint").textContent = "tick the vehicles first"; return; }
  const list = ids.map((id) => `<li>${vehiclesById.get(id)?.name || "vehicle " + id} (${id})</li>`).join("");
  const ans = await dialog(`${verb} ${ids.length} vehicles?`, `<p>Every target:</p><ul class="targets">${list}</ul>`,
    [["yes", `${verb} all ${ids.length}`], ["", "Cancel"]]);
  if (ans !== "yes") return;
  const r = await call("POST", "/api/commands", { command: verb, vehicles: ids });
  $("draw-hint").textContent = r.status === 200 ? r.body.results.map((x) => `${x.vehicle}: ${x.ok ? "ok" : x.error}`).join("; ")
    : `refused: ${r.body?.error}`;
}

/** The vehicles waiting for the operator's confirmation: a non-modal dialog with a Confirm per vehicle. */
function updateConfirm(vehicles) {
  const waiting = vehicles.filter((v) => v.confirmation_required);
  const d = $("confirm");
  const ul = $("confirm-list");
  const key = waiting.map((v) => `${v.id}:${v.mission?.node || ""}`).join(",");
  if (ul.dataset.key !== key) {
    ul.dataset.key = key;
    ul.innerHTML = waiting.map((v) => `<li data-vehicle="${v.id}">${v.name || "vehicle " + v.id}: ${v.mission?.node ||
      "the mission"} <button type="button" data-cmd data-confirm="${v.id}">Confirm</button></li>`).join("");
    for (const b of ul.querySelectorAll("[data-confirm]")) {
      b.addEventListener("click", () => call("POST", `/api/vehicles/${b.dataset.confirm}/user_confirm`));
    }
    applyRole();
  }
  if (waiting.length && !d.open) d.show();
  if (!waiting.length && d.open) d.close();
}

function onMessage(msg) {
  if (msg.type === "snapshot") {
    stats.snapshots += 1;
    pending = msg;
  } else if (msg.type === "event") {
    alerts.add(msg);
    const d = msg.data || {};
    const pos = Number.isFinite(d.lat) && Number.isFinite(d.lon) ? [d.lat, d.lon] : (d.position || d.point);
    if (msg.kind === "detection" && Array.isArray(pos) && getHome()) fmap.addDetection(pos[0], pos[1], msg.message);
  } else if (msg.type === "error") {
    $("draw-hint").textContent = `service: ${msg.error}`;
  }
}

function render(snap) {
  const t0 = performance.now();
  const now = snap.t;
  if (!getHome()) {
    const first = snap.vehicles.find((v) => v.position);
    if (!first) return;
    const q = new URLSearchParams(location.search).get("home");
    const h = q ? q.split(",").map(Number) : [first.position.lat, first.position.lon];
    setHome(h[0], h[1]);
  }
  if (fencePoints && !fenceDrawn) { fmap.setFence(fencePoints); fenceDrawn = true; }
  tasksById = new Map(snap.tasks.map((t) => [t.id, t]));
  vehiclesById = new Map(snap.vehicles.map((v) => [v.id, v]));
  for (const v of snap.vehicles) v.alert = v.confirmation_required ? "confirmation required" : alerts.of(v.id);
  fmap.updateTasks(snap.tasks);
  fmap.updateVehicles(snap.vehicles, tasksById, now);
  fleet.update(snap.vehicles);
  tasks.update(snap.tasks);
  panel.record(snap.vehicles, now);
  panel.update(vehiclesById.get(panel.vid));
  updateConfirm(snap.vehicles);
  const t1 = performance.now();
  stats.renderTimes.push(t1 - t0);
  if (stats.lastRender) stats.intervals.push(t1 - stats.lastRender);
  stats.lastRender = t1;
  stats.renders += 1;
  stats.seq = snap.seq;
  for (const k of ["renderTimes", "intervals"]) if (stats[k].length > 2000) stats[k].splice(0, 1000);
}

function frame(ts) {
  if (stats.lastFrame) stats.frameTimes.push(ts - stats.lastFrame);
  if (stats.frameTimes.length > 2000) stats.frameTimes.splice(0, 1000);
  stats.lastFrame = ts;
  if (pending) { const s = pending; pending = null; render(s); }
  if (stats.renders % 10 === 0 && stats.intervals?.length) {
    const iv = stats.intervals.slice(-20);
    $("stats").textContent = `map ${(1000 / (iv.reduce((a, b) => a + b, 0) / iv.length)).toFixed(1)} Hz`;
  }
  requestAnimationFrame(frame);
}

async function start() {
  const r = await call("GET", "/api/whoami");
  if (r.status !== 200) {
    setToken(null);
    $("login").hidden = false;
    $("login-error").textContent = r.status === 401 ? "unknown token" : `the service answered ${r.status}`;
    return;
  }
  role = r.body.role;
  $("who").textContent = `${r.body.name}`;
  document.body.dataset.role = role;
  $("login").hidden = true;
  $("app").hidden = false;
  fmap = new FleetMap($("map"), pick);
  fleet = new FleetList(document.querySelector("#fleet tbody"), pick);
  tasks = new TaskList(document.querySelector("#tasks tbody"), cancelTask);
  alerts = new Alerts($("alerts"), $("alert-count"));
  live = new Live(onMessage, (up) => { $("link").textContent = up ? "live" : "offline"; $("link").className = `link ${up ? "ok" : "bad"}`; });
  joystick = new Joystick(live);
  panel = new VehiclePanel($("vehicle"), { joystick, canCommand, applyRole });
  for (const b of document.querySelectorAll("[data-draw]")) b.addEventListener("click", () => startDraw(b.dataset.draw));
  $("draw-finish").addEventListener("click", () => fmap.finish());
  $("draw-cancel").addEventListener("click", () => { fmap.cancelDraw(); endDraw(); $("draw-hint").textContent = ""; });
  $("multi-go").addEventListener("click", commandMany);
  const verbUi = { dialog, hint: (text) => { $("draw-hint").textContent = text; }, vehicles: () => vehiclesById,
    selected: () => panel.vid ?? null, canCommand, map: fmap };
  setupVerbs(verbUi);
  setupMissionUpload(verbUi);
  fenceDraw(verbUi);
  fmap.map.on("mousemove", (e) => {
    if (!getHome()) return;
    const [lat, lon] = [e.latlng.lat, e.latlng.lng];
    const q = toLocal(lat, lon);
    $("readout").textContent = `N ${q[0].toFixed(1)} m  E ${q[1].toFixed(1)} m   lat ${lat.toFixed(7)}  lon ${lon.toFixed(7)}`;
  });
  const fence = await call("GET", "/api/fence");
  fencePoints = fence.status === 200 && fence.body.points ? fence.body.points : null;
  applyRole();
  live.open();
  requestAnimationFrame(frame);
  window.taskflight = { stats, map: fmap, role: () => role, call, joystick, panel };
}

$("login").addEventListener("submit", (e) => { e.preventDefault(); setToken($("token").value.trim()); start(); });
$("logout").addEventListener("click", () => { setToken(null); location.reload(); });
const hash = new URLSearchParams(location.hash.slice(1)).get("token");
if (hash) { setToken(hash); history.replaceState(null, "", location.pathname + location.search); }
if (token()) start(); else $("login").hidden = false;
