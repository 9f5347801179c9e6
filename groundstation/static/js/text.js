// Text from the service is data, never markup: esc() for the few templates that build HTML, textEl() for
// Leaflet tooltips (a string given to Leaflet is parsed as HTML; an element is not).
const ENTITIES = { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" };

/** ``s`` safe inside HTML text and quoted attribute values. */
export function esc(s) { return String(s ?? "").replace(/[&<>"']/g, (c) => ENTITIES[c]); }

/** A <span> holding ``s`` as text (for Leaflet's bindTooltip / bindPopup). */
export function textEl(s) {
  const el = document.createElement("span");
  el.textContent = String(s ?? "");
  return el;
}
