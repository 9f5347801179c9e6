// Local metres around home <-> lat/lon (flat earth, as the ground tests do: < a few km; seed 003 Sec. II
// gives team tasks in lat/lon). Leaflet's L.CRS.Simple map uses [north, east] metres as its "latlng".
const M_PER_DEG = 111320.0;
let home = null;

export function setHome(lat, lon) { home = [lat, lon]; }
export function getHome() { return home; }

/** [north, east] metres of (lat, lon) from home. */
export function toLocal(lat, lon) {
  return [(lat - home[0]) * M_PER_DEG, (lon - home[1]) * M_PER_DEG * Math.cos(home[0] * Math.PI / 180)];
}

/** [lat, lon] of the point ``n`` m north and ``e`` m east of home. */
export function toGeo(n, e) {
  return [home[0] + n / M_PER_DEG, home[1] + e / (M_PER_DEG * Math.cos(home[0] * Math.PI / 180))];
}

const PALETTE = ["#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324",
  "#469990", "#800000", "#808000", "#000075", "#e6beff", "#aaffc3", "#ffd8b1", "#fabebe"];

/** The vehicle's colour on the map and in the lists. */
export function colour(vid) { return PALETTE[(vid - 1) % PALETTE.length]; }
