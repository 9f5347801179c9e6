// The operator's web UI (seed 003 Sec. II, the Team Control interface): login, the live stream,
// the map, the lists, the vehicle panel and the dialogs. Snapshots arrive at 10 Hz; the latest is drawn
// in the next animation frame (stats in window.taskflight.stats for the bench and the tests).
import { call, Live, setToken, token } from "./api.js";
import { fenceDraw } from "./fence_draw.js";
import { getHome, setHome, toLocal } from "./geo.js";
import { Joystick } from "./joystick.js";
import { Alerts, FleetList, linkOf, TaskList } from "./lists.js";
import { FleetMap } from "./map.js";
import { setupMissionUpload } from "./mission_upload.js";
import { installShortcuts } from "./shortcuts.js";
import { esc } from "./text.js";
import { VehiclePanel } from "./vehicle.js";
import { cancelTaskAsking, setupVerbs } from "./verbs.js";

const $ = (id) => document.getElementById(id);
const stats = { snapshots: 0, renders: 0, renderTimes: [], frameTimes: [], intervals: [], lastRender: 0, lastFrame: 0, seq: 0 };
let role = null, live = null, fmap = null, fleet = null, tasks = null, alerts = null, panel = null, joystick = null;
let pending = null, vehiclesById = new Map(), tasksById = new Map();
let fencePoints = null, fenceDrawn = false;
// the header: "live" only while snapshots arrive; "stale" when none came for STALE_MS (the socket may
// still be open: a stopped or hung service), "offline" when the socket is closed too
const STALE_MS = 2000;
let lastSnapshotAt = 0, socketUp = false;

/** A modal dialog; resolves to the value of the button pressed. */
function dialog(title, bodyHtml, buttons) {
  const d = $("dialog");
  $("dialog-title").textContent = title;
  $("dialog-body").innerHTML = bodyHtml;
  $("dialog-buttons").innerHTML = buttons.map(([v, label]) => `<button value="${esc(v)}" data-answer="${esc(v)}">${esc(label)}</button>`).join("");
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
    const ans = await dialog("Fewer vehicles free", `<p>${esc(body.vehicles)} vehicles asked for; ${esc(r.body.free)} free.
      The service offers N = <b class="offer">${esc(r.body.offer)}</b>.</p>`,
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

async function releaseTasks(ids) {
  const what = ids ? `task${ids.length > 1 ? "s" : ""} ${ids.join(", ")}` : "every held task";
  const ans = await dialog(`Release ${what}?`, "<p>Held tasks come from an earlier run. Released, the vehicles divide and fly them.</p>",
    [["yes", "Release"], ["", "Cancel"]]);
  if (ans !== "yes") return;
  const r = await call("POST", "/api/tasks/release", ids ? { ids } : {});
  $("draw-hint").textContent = r.status === 200 ? `released ${r.body.released.join(", ") || "nothing"}` : `refused: ${r.body?.error}`;
}

async function ackAlert(id) {
  const r = await call("POST", `/api/events/${id}/ack`);
  if (r.status === 200) alerts.acked(r.body.id, r.body.acked_by, r.body.acked_at);
  else $("draw-hint").textContent = `acknowledgement refused: ${r.body?.error}`;
}

/** The alerts the service keeps (every (re)connect: nothing lost by a reload or a dropped socket). */
async function loadAlerts() {
  const r = await call("GET", "/api/alerts?limit=200");
  if (r.status === 200) alerts.load(r.body.alerts, r.body.kinds);
  applyRole();
}

/** The replay: the selected vehicle's stored track of the last ``minutes`` drawn on the map. */
async function replay() {
  const vid = fleet.selected;
  if (vid == null) { $("draw-hint").textContent = "click a vehicle first, then Replay"; return; }
  if (fmap.replay) { fmap.showReplay(vid, null); $("replay-go").textContent = "Replay"; return; }
  const minutes = Number($("replay-min").value) || 10;
  const now = Date.now() / 1000;
  const r = await call("GET", `/api/track/${vid}?since=${now - minutes * 60}&until=${now}`);
  if (r.status !== 200) { $("draw-hint").textContent = `replay refused: ${r.body?.error}`; return; }
  const n = fmap.showReplay(vid, r.body.points);
  $("draw-hint").textContent = `vehicle ${vid}: ${n} samples of the last ${minutes} min`;
  $("replay-go").textContent = n ? "Clear replay" : "Replay";
}

function headerState() {
  const fresh = lastSnapshotAt && performance.now() - lastSnapshotAt <= STALE_MS;
  const state = socketUp && fresh ? "live" : lastSnapshotAt && !fresh ? "stale" : socketUp ? "waiting" : "offline";
  const el = $("link");
  const age = lastSnapshotAt ? ((performance.now() - lastSnapshotAt) / 1000).toFixed(0) : null;
  const text = state === "stale" ? `stale (${age} s${socketUp ? "" : ", offline"})` : state;
  if (el.textContent !== text) el.textContent = text;
  el.className = `link ${state === "live" ? "ok" : state === "stale" ? "warn" : "bad"}`;
  el.dataset.state = state;
}

function cancelTask(t) {  // a piece of a divided task asks whether the whole group goes (verbs.js)
  return cancelTaskAsking(t, tasksById, dialog, (text) => { $("draw-hint").textContent = text; });
}

async function commandMany() {
  const ids = fleet.ticked();
  const verb = $("multi-cmd").value;
  if (!ids.length) { $("draw-hint").textContent = "tick the vehicles first"; return; }
  const list = ids.map((id) => `<li>${esc(vehiclesById.get(id)?.name || "vehicle " + id)} (${esc(id)})</li>`).join("");
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
    ul.innerHTML = waiting.map((v) => `<li data-vehicle="${esc(v.id)}">${esc(v.name || "vehicle " + v.id)}: ${esc(v.mission?.node ||
      "the mission")} <button type="button" data-cmd data-confirm="${esc(v.id)}">Confirm</button></li>`).join("");
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
    lastSnapshotAt = performance.now();
    pending = msg;
  } else if (msg.type === "hello") {
    loadAlerts();
  } else if (msg.type === "ack") {
    alerts.acked(msg.id, msg.acked_by, msg.acked_at);
  } else if (msg.type === "event") {
    if (alerts.add(msg)) applyRole();
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
  for (const v of snap.vehicles) {
    v.alert = v.confirmation_required ? "confirmation required" : alerts.of(v.id);
    v.link = linkOf(v, snap.stale_s, snap.lost_s);
  }
  const held = snap.tasks.filter((t) => t.state === "held").length;
  $("release-all").hidden = !held;
  $("release-all").textContent = `Release ${held} held task${held === 1 ? "" : "s"}`;
  fmap.updateTasks(snap.tasks);
  fmap.updateVehicles(snap.vehicles, tasksById, now);
  fleet.update(snap.vehicles);
  const taskRows = tasks.rows.size;
  tasks.update(snap.tasks);
  if (tasks.rows.size !== taskRows) applyRole();  // new rows' buttons: disabled for an observer
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
  tasks = new TaskList(document.querySelector("#tasks tbody"), cancelTask, releaseTasks);
  alerts = new Alerts($("alerts"), $("alert-count"), ackAlert);
  live = new Live(onMessage, (up) => { socketUp = up; headerState(); });
  setInterval(headerState, 250);
  $("release-all").addEventListener("click", () => releaseTasks(null));
  $("replay-go").addEventListener("click", replay);
  joystick = new Joystick(live);
  panel = new VehiclePanel($("vehicle"), { joystick, canCommand, applyRole, dialog });
  for (const b of document.querySelectorAll("[data-draw]")) b.addEventListener("click", () => startDraw(b.dataset.draw));
  $("draw-finish").addEventListener("click", () => fmap.finish());
  $("draw-cancel").addEventListener("click", () => { fmap.cancelDraw(); endDraw(); $("draw-hint").textContent = ""; });
  $("multi-go").addEventListener("click", commandMany);
  installShortcuts(() => fmap.map.invalidateSize());
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
