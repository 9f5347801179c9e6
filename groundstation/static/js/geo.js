// Local metres around home <-> lat/lon: ArduPilot's flat earth, the one of taskflight_common/geo.py
// (RADIUS_OF_EARTH 6378100 m, longitude scaled by cos(latitude) never below 0.01), written here again
// only because the browser cannot import Python; tests/test_ui_geo.py holds the two to the same numbers.
// Team tasks are given in lat/lon (seed 003 Sec. II). Leaflet's L.CRS.Simple map uses [north, east]
// metres (the local NED frame's horizontal part) as its "latlng".
export const M_PER_DEG = 0.011131884502145034 * 1e7;
const lonScale = (lat) => Math.max(Math.cos(lat * Math.PI / 180), 0.01);
let home = null;

export function setHome(lat, lon) { home = [lat, lon]; }
export function getHome() { return home; }

/** [north, east] metres of (lat, lon) from home (ArduPilot's Location::get_distance_NE). */
export function toLocal(lat, lon) {
  let dlon = lon - home[1];
  if (dlon > 180) dlon -= 360; else if (dlon < -180) dlon += 360;
  return [(lat - home[0]) * M_PER_DEG, dlon * M_PER_DEG * lonScale((lat + home[0]) / 2)];
}

/** [lat, lon] of the point ``n`` m north and ``e`` m east of home (ArduPilot's Location::offset). */
export function toGeo(n, e) {
  const dlat = n / M_PER_DEG;
  let lon = home[1] + e / (M_PER_DEG * lonScale(home[0] + dlat / 2));
  if (lon > 180) lon -= 360; else if (lon < -180) lon += 360;
  return [home[0] + dlat, lon];
}

const PALETTE = ["#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324",
  "#469990", "#800000", "#808000", "#000075", "#e6beff", "#aaffc3", "#ffd8b1", "#fabebe"];

/** The vehicle's colour on the map and in the lists. */
export function colour(vid) { return PALETTE[(vid - 1) % PALETTE.length]; }
