// The map (seed 003 Sec. II "All UAVs and tasks are displayed on a map, which is also
// used to input new tasks"): Leaflet in Web Mercator (its default CRS, EPSG:3857), everything at its
// latitude and longitude; the base layer is the service's offline raster tiles (GET /api/map: an MBTiles
// file served at /tiles/{z}/{x}/{y}.png, or a URL template) or, without tiles, a scale grid in metres from
// home over whatever the view shows.
import { call } from "./api.js";
import { colour, getHome, toGeo, toLocal } from "./geo.js";
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
    this.map = L.map(el, { minZoom: 3, maxZoom: 23, zoomSnap: 0.25, attributionControl: false,
      doubleClickZoom: false });
    this.map.setView([0, 0], 3);
    L.control.scale({ imperial: false, maxWidth: 150 }).addTo(this.map);
    this.centred = false;
    this.tiles = null;   // the tile layer, when the service has tiles
    this.grid = L.layerGroup().addTo(this.map);  // the scale grid, without tiles
    this.map.on("moveend zoomend", () => this._drawGrid());
    call("GET", "/api/map").then((r) => { if (r.status === 200 && r.body?.tiles) this.setTiles(r.body.tiles); });
    this.vehicles = new Map();  // vid -> {marker, track, target, pts}
    this.tasks = new Map();     // tid -> {layer, key}
    this.detections = L.layerGroup().addTo(this.map);
    this.onPick = onPick;
    this.draw = null;
    this.drawLayer = L.layerGroup().addTo(this.map);
    this.map.on("click", (e) => this._click(e));
    this.map.on("dblclick", () => { if (this.draw && this.draw.type !== "visit") this.finish(); });
  }

  /** The base layer: raster tiles from ``info.url`` ({z}/{x}/{y}), drawn beyond their deepest zoom. */
  setTiles(info) {
    if (this.tiles) this.tiles.remove();
    // not drawn below the file's shallowest zoom: a minNativeZoom far below the view's zoom would make Leaflet
    // walk every tile of the world at that zoom
    const opts = { minZoom: info.minzoom ?? 0, maxZoom: 23, maxNativeZoom: info.maxzoom ?? 19,
      className: "basemap", attribution: info.attribution || "" };
    if (Array.isArray(info.bounds) && info.bounds.length === 4) {
      const b = info.bounds;  // MBTiles: west, south, east, north
      opts.bounds = L.latLngBounds([b[1], b[0]], [b[3], b[2]]);
    }
    this.tiles = L.tileLayer(info.url, opts).addTo(this.map);
    this.tiles.bringToBack();
    this.grid.clearLayers();
  }

  /** Home is known: the view goes there (once) and the home mark is drawn. */
  _centre() {
    const h = getHome();
    if (this.centred || !h) return;
    this.centred = true;
    this.map.setView(h, 19);
    L.circleMarker(h, { radius: 5, color: "#000", fillOpacity: 0 }).bindTooltip("home").addTo(this.map);
    this._drawGrid();
  }

  /** Without tiles: lines every 1, 2 or 5 x 10^k m from home (about ten across the view), labelled. */
  _drawGrid() {
    this.grid.clearLayers();
    if (this.tiles || !getHome()) return;
    const b = this.map.getBounds();
    const [n0, e0] = toLocal(b.getSouth(), b.getWest());
    const [n1, e1] = toLocal(b.getNorth(), b.getEast());
    const span = Math.max(n1 - n0, e1 - e0, 1);
    const p10 = 10 ** Math.floor(Math.log10(span / 10));
    const step = [1, 2, 5, 10].map((k) => k * p10).find((s) => span / s <= 12);
    const lines = [];
    for (let i = Math.floor(e0 / step); i <= Math.ceil(e1 / step); i++) {
      const w = i === 0 ? 1.5 : 0.6;
      lines.push(L.polyline([toGeo(n0 - step, i * step), toGeo(n1 + step, i * step)],
        { color: "#999", weight: w, interactive: false, className: "grid" }));
    }
    for (let j = Math.floor(n0 / step); j <= Math.ceil(n1 / step); j++) {
      const w = j === 0 ? 1.5 : 0.6;
      lines.push(L.polyline([toGeo(j * step, e0 - step), toGeo(j * step, e1 + step)],
        { color: "#999", weight: w, interactive: false, className: "grid" }));
    }
    for (const l of lines) l.addTo(this.grid);
    const label = L.divIcon({ className: "gridlabel", iconSize: [0, 0], html: `<span>grid ${step} m</span>` });
    L.marker(toGeo(n0 + (n1 - n0) * 0.03, e0 + (e1 - e0) * 0.01), { icon: label, interactive: false, keyboard: false })
      .addTo(this.grid);
  }

  /** Vehicles: icon with heading, name and colour; track; dashed line to the current target. */
  updateVehicles(vehicles, tasksById, now) {
    this._centre();
    for (const v of vehicles) {
      if (!v.position) continue;
      const p = [v.position.lat, v.position.lon];
      const ne = toLocal(v.position.lat, v.position.lon);
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
        e.el.dataset.n = ne[0].toFixed(2);
        e.el.dataset.e = ne[1].toFixed(2);
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
      if (!last || Math.hypot(last[3] - ne[0], last[4] - ne[1]) > 0.3 || now - last[2] > 2) {
        e.pts.push([p[0], p[1], now, ne[0], ne[1]]);
      }
      while (e.pts.length && now - e.pts[0][2] > TRACK_S) e.pts.shift();
      e.track.setLatLngs(e.pts.map((q) => [q[0], q[1]]));
      e.track.setStyle({ color: link === "lost" ? GREY : colour(v.id), dashArray: link === "lost" ? "2 4" : null });
      const t = v.task != null ? tasksById.get(v.task) : null;
      const goal = t && t.points.length ? [t.points[0][0], t.points[0][1]] : null;
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
      const pts = t.points.map((q) => [q[0], q[1]]);
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
    this.fence = L.polygon(points.map((q) => [q[0], q[1]]),
      { color: "#c00", weight: 2, dashArray: "6 4", fill: false, interactive: false, className: "fence" })
      .addTo(this.map);
  }

  addDetection(lat, lon, text) {
    L.circleMarker([lat, lon], { radius: 6, color: "#d00", fillColor: "#ff0", fillOpacity: 0.9 })
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
    const need = d.type === "area_scan" || d.type === "fence" ? 3 : d.type === "visit" ? 1 : 2;
    if (d.pts.length < need) return;
    this.cancelDraw();
    d.done(d.pts.map((p) => [p[0], p[1]]));
  }

  _click(e) {
    if (!this.draw) return;
    const p = [e.latlng.lat, e.latlng.lng];
    this.draw.pts.push(p);
    this.drawLayer.clearLayers();
    const pts = this.draw.pts;
    for (const q of pts) L.circleMarker(q, { radius: 4, color: "#000" }).addTo(this.drawLayer);
    const closed = this.draw.type === "area_scan" || this.draw.type === "fence";
    if (pts.length > 1) (closed ? L.polygon : L.polyline)(pts, { color: this.draw.type === "fence" ? "#c00" : "#000", dashArray: "3 3" })
      .addTo(this.drawLayer);
    if (this.draw.type === "visit") this.finish();
  }

  /** The replay: a vehicle's stored track (GET /api/track) drawn over the map, the samples as dots with
   * their time, mode and health; ``null`` clears it. */
  showReplay(vid, points) {
    if (this.replay) { this.replay.remove(); this.replay = null; }
    if (!points || !points.length) return 0;
    const pts = points.filter((q) => q.lat != null).map((q) => [[q.lat, q.lon], q]);
    const layer = L.layerGroup();
    L.polyline(pts.map(([p]) => p), { color: colour(vid), weight: 3, opacity: 0.9, dashArray: "1 5",
      className: "replay", interactive: false }).addTo(layer);
    for (const [p, q] of pts) {
      const dot = L.circleMarker(p, { radius: 2.5, color: colour(vid), fillOpacity: 1, className: "replay-dot" });
      dot.bindTooltip(textEl(`${new Date(q.t * 1000).toLocaleTimeString()} ${q.mode || ""} ${q.health || ""} alt ${(q.alt ?? 0).toFixed(1)} m`));
      dot.addTo(layer);
    }
    this.replay = layer.addTo(this.map);
    return pts.length;
  }

  /** The map's container pixel of the point ``n`` m north and ``e`` m east of home (for the tests). */
  pixelOf(n, e) { const p = this.map.latLngToContainerPoint(toGeo(n, e)); return [p.x, p.y]; }
}
