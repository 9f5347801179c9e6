// The break-in joystick (seed 000 Sec. VII: the operator breaks in and flies the vehicle):
// on-screen pad, keyboard (arrows / WASD, Q/E yaw, R/F up/down) and the Gamepad API, streamed over the
// WebSocket at 15 Hz as the service's {"type": "joystick", "vehicle", "lease", "values": [vn, ve, vd,
// yaw_rate], "validity_s", "seq", "t"}: ``t`` is this page's clock when the sample was made (the service
// learns the page's clock from {"type": "clock"} exchanges, answered here) and ``seq`` counts up, so a
// sample is flown only within its validity from the operator's hand and never after a newer one.
// Samples go only with the vehicle's stick lease (POST /api/vehicles/{vid}/stick/lease): one operator
// flies a vehicle at a time; another page sees who holds it and sends nothing.
import { call } from "./api.js";

const RATE_HZ = 15;
const VALIDITY_S = 0.3;
const KEYS = {
  ArrowUp: [0, 1], KeyW: [0, 1], ArrowDown: [0, -1], KeyS: [0, -1],
  ArrowRight: [1, 1], KeyD: [1, 1], ArrowLeft: [1, -1], KeyA: [1, -1],
  KeyF: [2, 1], KeyR: [2, -1], KeyE: [3, 1], KeyQ: [3, -1],
};

export class Joystick {
  constructor(live) {
    this.live = live;
    this.vehicle = null;
    this.lease = null;       // the lease id while this page holds the stick
    this.status = "";        // why this page does not hold it (the holder, a refusal)
    this.keys = new Set();
    this.pad = [0, 0];
    this.speed = 2.0;
    this.yawRate = 30.0;
    this.sent = 0;
    this.seq = 0;
    this.timer = null;
    this.last = [0, 0, 0, 0];
    window.addEventListener("keydown", (e) => this._key(e, true));
    window.addEventListener("keyup", (e) => this._key(e, false));
    window.addEventListener("blur", () => this.keys.clear());
    window.addEventListener("pagehide", () => this.engage(null));
    const onMessage = live.onMessage;
    live.onMessage = (msg) => {
      if (msg.type === "clock") { live.send({ type: "clock", t: msg.t, page_t: performance.now() }); return; }
      if (msg.type === "error" && msg.vehicle != null && msg.vehicle === this.vehicle &&
          /lease|held by|take the stick/.test(msg.error || "")) this._lost(msg.error);
      onMessage(msg);
    };
  }

  _key(e, down) {
    if (this.lease == null || !(e.code in KEYS)) return;
    if (e.target && ["INPUT", "SELECT", "TEXTAREA"].includes(e.target.tagName)) return;
    e.preventDefault();
    if (down) this.keys.add(e.code); else this.keys.delete(e.code);
  }

  /** Take ``vid``'s stick and stream to it (null: stop and release). Resolves to true when this page
   * holds the stick; else ``status`` says who does. */
  async engage(vid) {
    const old = { vehicle: this.vehicle, lease: this.lease };
    this._stop();
    this.vehicle = vid;
    this.status = "";
    if (old.lease && old.vehicle != null) {
      call("DELETE", `/api/vehicles/${old.vehicle}/stick/lease?lease_id=${encodeURIComponent(old.lease)}`);
    }
    if (vid == null) { this.keys.clear(); return false; }
    const r = await call("POST", `/api/vehicles/${vid}/stick/lease`);
    if (this.vehicle !== vid) {  // changed meanwhile: let go of what was just taken
      if (r.status === 200) call("DELETE", `/api/vehicles/${vid}/stick/lease?lease_id=${encodeURIComponent(r.body.lease_id)}`);
      return false;
    }
    if (r.status !== 200) { this.status = r.body?.error || `stick lease refused (${r.status})`; return false; }
    this.lease = r.body.lease_id;
    this.timer = setInterval(() => this._tick(), 1000 / RATE_HZ);
    return true;
  }

  /** True while this page holds ``vid``'s stick. */
  holds(vid) { return this.lease != null && this.vehicle === vid; }

  _stop() {
    clearInterval(this.timer);
    this.timer = null;
    this.lease = null;
  }

  _lost(why) {
    this._stop();
    this.keys.clear();
    this.status = why;
  }

  /** The current stick: [v_north, v_east, v_down, yaw_rate]. */
  values() {
    const v = [0, 0, 0, 0];
    for (const k of this.keys) { const [i, s] = KEYS[k]; v[i] += s; }
    v[0] += this.pad[1]; v[1] += this.pad[0];
    for (const gp of navigator.getGamepads ? navigator.getGamepads() : []) {
      if (!gp) continue;
      const dz = (x) => (Math.abs(x) < 0.1 ? 0 : x);
      v[0] += -dz(gp.axes[1] || 0); v[1] += dz(gp.axes[0] || 0);
      v[3] += dz(gp.axes[2] || 0); v[2] += dz(gp.axes[3] || 0);
    }
    const clamp = (x) => Math.max(-1, Math.min(1, x));
    return [clamp(v[0]) * this.speed, clamp(v[1]) * this.speed, clamp(v[2]) * this.speed * 0.5,
      clamp(v[3]) * this.yawRate];
  }

  _tick() {
    if (this.vehicle == null || this.lease == null) return;
    this.last = this.values();
    this.seq += 1;
    if (this.live.send({ type: "joystick", vehicle: this.vehicle, lease: this.lease, values: this.last,
      validity_s: VALIDITY_S, seq: this.seq, t: performance.now() })) this.sent += 1;
  }

  /** The on-screen pad inside ``el`` (a .pad with a .knob). */
  bindPad(el) {
    const knob = el.querySelector(".knob");
    const move = (ev) => {
      const r = el.getBoundingClientRect();
      let x = (ev.clientX - r.left - r.width / 2) / (r.width / 2);
      let y = -(ev.clientY - r.top - r.height / 2) / (r.height / 2);
      const m = Math.hypot(x, y);
      if (m > 1) { x /= m; y /= m; }
      this.pad = [x, y];
      knob.style.left = `${45 + x * 45}px`;
      knob.style.top = `${45 - y * 45}px`;
    };
    const up = () => { this.pad = [0, 0]; knob.style.left = "45px"; knob.style.top = "45px"; };
    el.addEventListener("pointerdown", (ev) => { el.setPointerCapture(ev.pointerId); move(ev); });
    el.addEventListener("pointermove", (ev) => { if (el.hasPointerCapture(ev.pointerId)) move(ev); });
    el.addEventListener("pointerup", up);
    el.addEventListener("pointercancel", up);
  }
}
