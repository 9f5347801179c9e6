// The ground service's REST API and live WebSocket, as the UI uses them.
const KEY = "taskflight.token";

export function token() { return sessionStorage.getItem(KEY); }
export function setToken(t) { if (t) sessionStorage.setItem(KEY, t); else sessionStorage.removeItem(KEY); }

/** A REST call; resolves to {status, body} (never throws on an HTTP refusal). */
export async function call(method, path, body) {
  const init = { method, headers: { Authorization: `Bearer ${token()}` } };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  let r;
  try { r = await fetch(path, init); } catch (e) { return { status: 0, body: { error: String(e) } }; }
  let data = null;
  try { data = await r.json(); } catch { data = null; }
  return { status: r.status, body: data };
}

/** The live stream: snapshots and events to ``onMessage``; reconnects with a back-off. */
export class Live {
  constructor(onMessage, onState) {
    this.onMessage = onMessage;
    this.onState = onState;
    this.sock = null;
    this.closed = false;
    this.delay = 500;
  }

  open() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const sock = new WebSocket(`${proto}://${location.host}/api/ws`);
    this.sock = sock;
    sock.onopen = () => { sock.send(JSON.stringify({ type: "auth", token: token() })); this.delay = 500; };
    sock.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch { return; }
      if (msg.type === "hello") this.onState(true, msg);
      this.onMessage(msg);
    };
    sock.onclose = () => {
      this.onState(false);
      if (!this.closed) setTimeout(() => this.open(), this.delay);
      this.delay = Math.min(5000, this.delay * 2);
    };
  }

  send(msg) {
    if (this.sock && this.sock.readyState === WebSocket.OPEN) { this.sock.send(JSON.stringify(msg)); return true; }
    return false;
  }

  close() { this.closed = true; if (this.sock) this.sock.close(); }
}
