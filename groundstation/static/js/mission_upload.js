// A Task Specification Tree (seed 000 Sec. III) uploaded to one vehicle from the page: a file chosen here or
// one of the service's bundled missions (GET /api/mission_files). The service reads the file's YAML
// (POST /api/mission_files/parse) and forwards the tree to the vehicle (POST /api/vehicles/{vid}/mission); the
// vehicle's delegation answers (seed 000 Sec. IV: accepted, or rejected with reasons naming the nodes), and
// the answer is drawn node by node on the tree that was sent.
import { call } from "./api.js";
import { esc } from "./text.js";

const REASON = /^node (\S+) \(([^)]*)\): (.*)$/s;

/** {nodeId: [reason, ...]} and the reasons naming no node. */
export function reasonsByNode(reasons) {
  const byNode = {}, general = [];
  for (const r of reasons || []) {
    const m = REASON.exec(String(r));
    if (m) (byNode[m[1]] ||= []).push(m[3]); else general.push(String(r));
  }
  return { byNode, general };
}

/** The tree as nested lists, each node marked accepted / refused (with its reasons) / not named. */
export function renderTree(node, byNode, accepted) {
  const id = node.id ?? "";
  const mine = byNode[String(id)] || [];
  const cls = accepted ? "accepted" : mine.length ? "refused" : "unnamed";
  const mark = accepted ? "✓ accepted" : mine.length ? "✗ refused" : "—";
  const why = mine.map((r) => `<li class="reason">${esc(r)}</li>`).join("");
  const kids = (node.children || []).map((c) => renderTree(c, byNode, accepted)).join("");
  return `<li class="node ${cls}" data-node="${esc(id)}"><b>${esc(id)}</b> <small>${esc(node.type)}</small>
    <span class="verdict">${mark}</span>${why ? `<ul class="reasons">${why}</ul>` : ""}${kids ? `<ul>${kids}</ul>` : ""}</li>`;
}

/** Wires the mission upload panel. ``ui``: {dialog, hint(text), vehicles() -> Map, selected() -> vid|null,
 * canCommand()}. */
export function setupMissionUpload(ui) {
  const $ = (id) => document.getElementById(id);
  const sel = $("mu-vehicle"), bundled = $("mu-bundled"), file = $("mu-file"), out = $("mu-result");
  if (!sel) return null;

  call("GET", "/api/mission_files").then((r) => {
    if (r.status !== 200) return;
    for (const name of r.body.missions) {
      const o = document.createElement("option");
      o.value = name; o.textContent = name;
      bundled.appendChild(o);
    }
  });
  let key = "";
  setInterval(() => {  // the vehicles to choose from follow the fleet
    const vs = [...ui.vehicles().values()];
    const k = vs.map((v) => `${v.id}:${v.name}`).join(",");
    if (k === key) return;
    key = k;
    const keep = sel.value;
    sel.replaceChildren(...vs.map((v) => {
      const o = document.createElement("option");
      o.value = v.id; o.textContent = `${v.id} ${v.name || ""}`;
      return o;
    }));
    if (keep) sel.value = keep;
  }, 500);

  async function missionBody() {
    if (file.files && file.files.length) {
      const text = await file.files[0].text();
      return [file.files[0].name, await call("POST", "/api/mission_files/parse", { text })];
    }
    if (!bundled.value) return [null, { status: 0, body: { error: "choose a file or a bundled mission" } }];
    return [bundled.value, await call("GET", `/api/mission_files/${encodeURIComponent(bundled.value)}`)];
  }

  async function upload() {
    if (!ui.canCommand()) return;
    const vid = Number(sel.value || ui.selected());
    if (!vid) { out.textContent = "choose a vehicle"; return; }
    const [source, r] = await missionBody();
    if (r.status !== 200) { out.dataset.state = "error"; out.textContent = `not sent: ${r.body?.error || r.status}`; return; }
    const m = r.body;
    const start = $("mu-start").checked;
    const ans = await ui.dialog(`Upload mission ${m.mission} to vehicle ${vid}?`,
      `<p>${esc(source)}: <b>${esc(m.mission)}</b> ${esc(m.description)}</p><p>Vehicle ${esc(vid)} leaves the team
      (a directed command)${start ? " and starts the mission at once" : ""}.</p>`, [["yes", "Upload"], ["", "Cancel"]]);
    if (ans !== "yes") return;
    out.dataset.state = "sending";
    out.textContent = "delegating...";
    const a = await call("POST", `/api/vehicles/${vid}/mission`, { ...m, start });
    const accepted = a.status === 200;
    if (!accepted && a.status !== 422) {
      out.dataset.state = "error";
      out.textContent = `vehicle ${vid}: ${a.body?.error || a.status}`;
      return;
    }
    const { byNode, general } = reasonsByNode(accepted ? [] : a.body?.reasons);
    const head = accepted ? `vehicle ${esc(vid)} accepted ${esc(m.mission)}` :
      `vehicle ${esc(vid)} rejected ${esc(m.mission)}: ${Object.keys(byNode).length} node(s) refused`;
    out.dataset.state = accepted ? "accepted" : "rejected";
    out.innerHTML = `<p class="${accepted ? "ok" : "error"}">${head}</p>` +
      (general.length ? `<ul class="reasons">${general.map((g) => `<li>${esc(g)}</li>`).join("")}</ul>` : "") +
      `<ul class="tree">${renderTree(m.tree, byNode, accepted)}</ul>`;
    ui.hint(accepted ? `mission ${m.mission} accepted by vehicle ${vid}` : `mission ${m.mission} rejected by vehicle ${vid}`);
  }

  $("mu-go").addEventListener("click", upload);
  bundled.addEventListener("change", () => { if (bundled.value) file.value = ""; });
  return { upload };
}
