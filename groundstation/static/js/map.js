// The map (seed 003 Sec. II "All UAVs and tasks are displayed on a map, which is also
// used to input new tasks"): Leaflet with L.CRS.Simple in local metres around home, no tiles.
import { colour, toGeo, toLocal } from "./geo.js";
import { esc, textEl } from "./text.js";

const L = window.L;
const TRACK_S = 180;  // the track's length (s)
const GREY = "#888";

function arrow(c) {
  return `<svg width="24" height="24" viewBox="-12 -12 24 24"><g class="hdg">
    <path d="M0,-11 L7,8 L0,4 L-7,8 Z" fill="${c}" stroke="#000" stroke-width="1"/></g></svg>`;
}

export class FleetMap {
  constructor(el, onPick) {
    this.map = L.map(el, { crs: L.CRS.Simple, minZoom: -3, maxZoom: 6, zoomSnap: 0.25,
      attributionControl: false, doubleClickZoom: false });
    this.map.setView([0, 0], 2);
    L.control.scale({ imperial: false, maxWidth: 150 }).addTo(this.map);
    // a 10 m grid and home, drawn once (no tiles: offline)
    const grid = [];
    for (let i = -500; i <= 500; i += 10) {
      const w = i % 100 === 0 ? 1 : 0.3;
      grid.push(L.polyline([[i, -500], [i, 500]], { color: "#bbb", weight: w, interactive: false }));
      grid.push(L.polyline([[-500, i], [500, i]], { color: "#bbb", weight: w, interactive: false }));
    }
    L.layerGroup(grid).addTo(this.map);
    L.circleMarker([0, 0], { radius: 5, color: "#000", fillOpacity: 0 }).bindTooltip("home").addTo(this.map);
    this.vehicles = new Map();  // vid -> {marker, track, target, pts}
    this.tasks = new Map();     // tid -> {layer, key}
    this.detections = L.layerGroup().addTo(this.map);
    this.onPick = onPick;
    this.draw = null;
    this.drawLayer = L.layerGroup().addTo(this.map);
    this.map.on("click", (e) => this._click(e));
    this.map.on("dblclick", () => { if (this.draw && this.draw.type !== "visit") this.finish(); });
  }

  /** Vehicles: icon with heading, name and colour; track; dashed line to the current target. */
  updateVehicles(vehicles, tasksById, now) {
    for (const v of vehicles) {
      if (!v.position) continue;
      const p = toLocal(v.position.lat, v.position.lon);
      let e = this.vehicles.get(v.id);
      if (!e) {
        const c = colour(v.id);
        const icon = L.divIcon({ className: "", iconSize: [0, 0],
          html: `<div class="vmarker" data-vehicle="${esc(v.id)}">${arrow(c)}<span class="label"></span></div>` });
        const marker = L.marker(p, { icon, keyboard: false }).addTo(this.map);
        marker.on("click", () => this.onPick(v.id));
        const track = L.polyline([], { color: c, weight: 2, opacity: 0.6, interactive: false }).addTo(this.map);
        const target = L.polyline([], { color: c, weight: 1.5, dashArray: "4 4", interactive: false }).addTo(this.map);
        e = { marker, track, target, pts: [], el: null };
        this.vehicles.set(v.id, e);
      }
      e.marker.setLatLng(p);
      if (!e.el) e.el = e.marker.getElement()?.querySelector(".vmarker");
      const link = v.link || "live";
      if (e.el) {
        e.el.dataset.n = p[0].toFixed(2);
        e.el.dataset.e = p[1].toFixed(2);
        e.el.dataset.link = link;
        e.el.classList.toggle("stale", link === "stale");
        e.el.classList.toggle("lost", link === "lost");
        e.el.querySelector(".hdg").setAttribute("transform", `rotate(${v.heading || 0})`);
        const age = v.age_s != null ? ` ${v.age_s.toFixed(0)} s` : "";
        const state = link === "live" ? "" : `${link}${age}`;
        const key = `${v.name}\u0000${v.alert || ""}\u0000${state}`;
        if (e.labelKey !== key) {  // the name, the link state and the alert as text
          e.labelKey = key;
          const label = e.el.querySelector(".label");
          label.textContent = v.name || `vehicle ${v.id}`;
          if (state) { const s = textEl(state); s.className = "linkstate"; label.append(" ", s); }
          if (v.alert) { const w = textEl(` ⚠ ${v.alert}`); w.className = "alert"; label.append(" ", w); }
        }
      }
      const last = e.pts[e.pts.length - 1];
      if (!last || Math.hypot(last[0] - p[0], last[1] - p[1]) > 0.3 || now - last[2] > 2) e.pts.push([p[0], p[1], now]);
      while (e.pts.length && now - e.pts[0][2] > TRACK_S) e.pts.shift();
      e.track.setLatLngs(e.pts.map((q) => [q[0], q[1]]));
      e.track.setStyle({ color: link === "lost" ? GREY : colour(v.id), dashArray: link === "lost" ? "2 4" : null });
      const t = v.task != null ? tasksById.get(v.task) : null;
      const goal = t && t.points.length ? toLocal(t.points[0][0], t.points[0][1]) : null;
      e.target.setLatLngs(goal ? [p, goal] : []);
    }
  }

  /** Tasks by type, coloured by their assignee, unassigned grey; finished ones faded, cancelled hidden. */
  updateTasks(tasks) {
    const seen = new Set();
    for (const t of tasks) {
      seen.add(t.id);
      const key = `${t.state}/${t.holder}/${t.version}`;
      const old = this.tasks.get(t.id);
      if (old && old.key === key) continue;
      if (old) old.layer.remove();
      if (t.state === "cancelled") { this.tasks.set(t.id, { layer: L.layerGroup(), key }); continue; }
      const c = t.holder ? colour(t.holder) : GREY;
      const style = { color: c, weight: 3, opacity: t.state === "done" ? 0.3 : 0.9, fillOpacity: 0.15 };
      const pts = t.points.map((q) => toLocal(q[0], q[1]));
      let layer;
      if (t.kind === "visit" || pts.length === 1) layer = L.circleMarker(pts[0], { ...style, radius: 7 });
      else if (t.kind === "area_scan" || t.kind === "area") layer = L.polygon(pts, style);
      else layer = L.polyline(pts, { ...style, dashArray: t.kind.includes("border") ? "8 4" : null });
      layer.bindTooltip(textEl(`task ${t.id} ${t.kind} ${t.state}${t.holder ? " → " + t.holder : ""}`));
      layer.addTo(this.map);
      this.tasks.set(t.id, { layer, key });
    }
    for (const [id, e] of this.tasks) if (!seen.has(id)) { e.layer.remove(); this.tasks.delete(id); }
  }

  /** The operational fence (lat/lon vertices from GET /api/fence), dashed red. */
  setFence(points) {
    if (this.fence) this.fence.remove();
    this.fence = L.polygon(points.map((q) => toLocal(q[0], q[1])),
      { color: "#c00", weight: 2, dashArray: "6 4", fill: false, interactive: false, className: "fence" })
      .addTo(this.map);
  }

  addDetection(lat, lon, text) {
    L.circleMarker(toLocal(lat, lon), { radius: 6, color: "#d00", fillColor: "#ff0", fillOpacity: 0.9 })
      .bindTooltip(textEl(text)).addTo(this.detections);
  }

  /** Start entering a task of ``type``; ``done(points)`` gets [[lat, lon], ...]. */
  startDraw(type, done) {
    this.cancelDraw();
    this.draw = { type, pts: [], done };
  }

  cancelDraw() { this.draw = null; this.drawLayer.clearLayers(); }

  finish() {
    const d = this.draw;
    if (!d) return;
    const need = d.type === "area_scan" ? 3 : d.type === "visit" ? 1 : 2;
    if (d.pts.length < need) return;
    this.cancelDraw();
    d.done(d.pts.map((p) => toGeo(p[0], p[1])));
  }

  _click(e) {
    if (!this.draw) return;
    const p = [e.latlng.lat, e.latlng.lng];
    this.draw.pts.push(p);
    this.drawLayer.clearLayers();
    const pts = this.draw.pts;
    for (const q of pts) L.circleMarker(q, { radius: 4, color: "#000" }).addTo(this.drawLayer);
    if (pts.length > 1) (this.draw.type === "area_scan" ? L.polygon : L.polyline)(pts, { color: "#000", dashArray: "3 3" })
      .addTo(this.drawLayer);
    if (this.draw.type === "visit") this.finish();
  }

  /** The replay: a vehicle's stored track (GET /api/track) drawn over the map, the samples as dots with
   * their time, mode and health; ``null`` clears it. */
  showReplay(vid, points) {
    if (this.replay) { this.replay.remove(); this.replay = null; }
    if (!points || !points.length) return 0;
    const pts = points.filter((q) => q.lat != null).map((q) => [toLocal(q.lat, q.lon), q]);
    const layer = L.layerGroup();
    L.polyline(pts.map(([p]) => p), { color: colour(vid), weight: 3, opacity: 0.9, dashArray: "1 5",
      className: "replay", interactive: false }).addTo(layer);
    for (const [p, q] of pts) {
      const dot = L.circleMarker(p, { radius: 2.5, color: colour(vid), fillOpacity: 1, className: "replay-dot" });
      dot.bindTooltip(`${new Date(q.t * 1000).toLocaleTimeString()} ${q.mode || ""} ${q.health || ""} alt ${(q.alt ?? 0).toFixed(1)} m`);
      dot.addTo(layer);
    }
    this.replay = layer.addTo(this.map);
    return pts.length;
  }

  /** The map's container pixel of the point ``n`` m north and ``e`` m east of home (for the tests). */
  pixelOf(n, e) { const p = this.map.latLngToContainerPoint([n, e]); return [p.x, p.y]; }
}
