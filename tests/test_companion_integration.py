"""The companion flying each autopilot over loopback UDP.

Parametrised over the bundled model and ArduPilot's own copter SITL (``TASKFLIGHT_ARDUCOPTER``; the
ArduCopter half skips, saying why, without it). Per autopilot one process for the module, reached
through a wire tap that decodes what the companion sends, one :class:`QuadNode` with its HTTP
control surface, a pymavlink ground station. The tests run in file order as one flight (take-off,
three WithHor waypoints, a heading Point, a wait, a joystick ExtVel break-in ended by user_confirm,
pause_direct and run, pause_after_current, in-flight retarget, stop and reset, landing; the verbs
during a take-off; then a GCS override and the loss of the companion), and each also runs alone:
it first puts the vehicle where it needs it. Continuity is judged on the decoded wire messages.
Deadlines are wall time derived from simulated durations.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from companion.flight import Retarget
from harness.autopilot import AUTOPILOTS
from harness.flight_session import LAND_HERE, TAKEOFF, FlightSession
from harness.observer import GUIDED, LAND, LOITER, RTL
from harness.timing import wait_for
from harness.wire_tap import wire_violations

pytestmark = pytest.mark.integration

# 5x: the companion, the HTTP surface and the joystick feed run on the wall clock, so a slower
# autopilot leaves a loaded 2-core CI machine room to keep up
SPEEDUP = 5.0


@pytest.fixture(scope="module", params=AUTOPILOTS)
def f(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[FlightSession]:
    session = FlightSession(request.param, tmp_path_factory.mktemp(f"companion_{request.param}"), SPEEDUP)
    try:
        yield session
    finally:
        session.close()


def test_takeoff(f: FlightSession) -> None:
    f.ensure_on_ground()
    r = f.post("/commands", TAKEOFF)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["indices"] == [0] and len(body["ids"]) == 1
    assert f.post("/run").status_code == 200
    wait_for(lambda: f.phase() == "ENGAGED", f.wall(30), "airborne")
    st = f.status()
    assert st["queue_system_status"] == "RUNNING" and st["queue_status"] == "RUNNING"
    f.wait_finished(body["ids"][0], 15)
    f.wait_near((f.pos()[0], f.pos()[1], -5.0), 0.8, 10)
    snap = f.node.link.mirror.snapshot()
    assert snap.mode == GUIDED and snap.armed
    assert f.status()["current_command_status"] == "UNKNOWN"  # nothing after the take-off yet
    # the take-off was accepted the first time: no refusal, no second NAV_TAKEOFF
    assert not [e for e in f.node.link.commands.errors if "TAKEOFF" in e], list(f.node.link.commands.errors)
    assert f.tap.count("COMMAND_LONG") >= 3
    wait_for(lambda: f.status()["is_synced"], f.wall(3), "is_synced (POSITION_TARGET_LOCAL_NED echo)")


def test_three_waypoints_with_hor(f: FlightSession) -> None:
    f.ensure_airborne()
    wps = [(10.0, 0.0, 6.0), (10.0, 10.0, 8.0), (0.0, 10.0, 6.0)]
    ids = f.add(*({"horizontal": {"mode": "POS", "north": n, "east": e},
                   "vertical": {"mode": "WITH_HOR", "altitude": alt}, "end": {"e_h": True, "e_v": True}}
                  for n, e, alt in wps))
    for cid, (n, e, alt) in zip(ids, wps, strict=True):
        f.wait_finished(cid, 30)
        # the command ends when the reference arrives; the vehicle is close behind
        f.wait_near((n, e, -alt), 1.0, 5)
        assert f.status()["queue_status"] == "RUNNING"
    f.wait_near((0.0, 10.0, -6.0), 0.5, 5)


def test_heading_point(f: FlightSession) -> None:
    f.ensure_airborne()
    here = f.pos()
    point = (here[0] - 20.0, here[1] + 20.0)  # south-east of the vehicle
    (cid,) = f.add({"heading": {"mode": "POINT", "north": point[0], "east": point[1]}, "end": {"e_hd": True}})
    f.wait_finished(cid, 15)
    expected = math.atan2(point[1] - here[1], point[0] - here[0])
    wait_for(lambda: abs(math.remainder(f.node.link.mirror.snapshot().yaw - expected, 2 * math.pi))
             < math.radians(8), f.wall(5), "yaw towards the point")
    assert math.dist(f.pos()[:2], here[:2]) < 1.0


def test_wait(f: FlightSession) -> None:
    f.ensure_airborne()
    here = f.pos()
    t0 = f.sim_time()
    (cid,) = f.add({"end": {"e_wait": 3.0}})
    f.wait_finished(cid, 10)
    # two ticks of slack: the test reads its estimate of the autopilot clock between the node's ticks
    assert f.sim_time() - t0 >= 3.0 - 0.1
    assert math.dist(f.pos(), here) < 1.0


def test_joystick_ext_vel_until_user_confirm(f: FlightSession) -> None:
    f.ensure_airborne()
    (cid,) = f.add({"horizontal": {"mode": "EXT_VEL"}, "vertical": {"mode": "EXT_VEL"},
                    "heading": {"mode": "EXT_VEL"}, "end": {"e_user": True}})
    wait_for(lambda: f.status()["confirmation_required_status"], f.wall(3), "confirmation required")
    start = f.pos()
    t_end = f.sim_time() + 8.0  # 3 m at 1.5 m/s take 2 s plus the ramp; a loaded machine ticks late
    while f.sim_time() < t_end and f.pos()[0] - start[0] <= 3.0:
        # a joystick pushing north at 1.5 m/s, 10 Hz of simulated time; validity 2 s: a late HTTP round
        # trip on a busy machine must not let the sample go stale (the stale -> zero-velocity behavior
        # is the flight layer's unit tests' business)
        r = f.post("/external/ext_vel", {"values": [1.5, 0.0, 0.0, 0.0], "validity_s": 2.0})
        assert r.status_code == 200, r.text
        f.sim_wait(0.1)
    moved = f.pos()[0] - start[0]
    assert moved > 3.0, f"the joystick moved the vehicle only {moved:.2f} m north in 8 s"
    assert abs(f.pos()[1] - start[1]) < 1.0  # and north only
    velocity_only = [m for m in f.tap.kept() if m.type_mask & 0b111]
    assert velocity_only, "no velocity-only SET_POSITION_TARGET_LOCAL_NED on the wire"
    assert f.post("/user_confirm").status_code == 200
    f.wait_finished(cid, 3)
    f.wait_still(6)  # the stream went stale / the next command holds: it stops


def test_pause_direct_then_run(f: FlightSession) -> None:
    f.ensure_airborne()
    here = f.pos()
    target = (here[0], here[1] + 20.0, -6.0)
    (cid,) = f.add({"horizontal": {"mode": "POS", "north": target[0], "east": target[1], "speed": 3.0},
                    "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True, "e_v": True}})
    wait_for(lambda: f.speed() > 2.0, f.wall(8), "flying east")
    assert f.post("/pause_direct").status_code == 200
    st = f.status()
    assert st["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING"
    assert st["current_command_status"] == "PAUSED" and st["current_command_id"] == cid
    assert st["confirmation_required_status"]  # the hover routine ends on user_confirm
    f.wait_still(8)
    paused_at = f.pos()
    assert math.dist(paused_at, target) > 5.0
    f.sim_wait(2.0)
    assert math.dist(f.pos(), paused_at) < 0.8, "holds while paused"
    assert f.post("/run").status_code == 200
    assert f.status()["current_command_status"] == "RUNNING"
    f.wait_finished(cid, 20)
    f.wait_near(target, 1.0, 5)


def test_pause_after_current(f: FlightSession) -> None:
    f.ensure_airborne()
    a = (f.pos()[0] - 10.0, f.pos()[1], -6.0)
    b = (a[0], a[1] - 10.0, -6.0)
    ida, idb = f.add(*({"horizontal": {"mode": "POS", "north": n, "east": e},
                        "vertical": {"mode": "POS", "altitude": -d}, "end": {"e_h": True, "e_v": True}}
                       for n, e, d in (a, b)))
    wait_for(lambda: f.speed() > 1.0, f.wall(5), "flying to A")
    assert f.post("/pause_after_current", {"routine_id": "hover"}).status_code == 200
    assert f.status()["queue_status"] == "RUNNING"  # still flying the current command
    f.wait_finished(ida, 15)
    wait_for(lambda: f.status()["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING", f.wall(2), "pause")
    st = f.status()
    assert st["current_command_id"] == idb and st["current_command_status"] == "PAUSED"
    f.wait_near(a, 1.0, 5)
    f.wait_still(5)
    held = f.pos()
    f.sim_wait(2.0)
    # held on the (GPS-grade) estimate: decimetres of jitter, no drift
    assert math.dist(f.pos(), held) < 0.8 and f.status()["current_command_id"] == idb
    assert f.post("/user_confirm").status_code == 200  # ends the hover routine: on to B
    f.wait_finished(idb, 20)
    f.wait_near(b, 1.0, 5)


def test_retarget_in_flight(f: FlightSession) -> None:
    f.ensure_airborne()
    here = f.pos()
    far = (here[0] + 40.0, here[1], -6.0)
    (cid,) = f.add({"horizontal": {"mode": "POS", "north": far[0], "east": far[1], "speed": 4.0},
                    "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True, "e_v": True}})
    wait_for(lambda: f.speed() > 3.0, f.wall(8), "flying north")
    new = (here[0] + 10.0, here[1] + 10.0, -7.0)
    f.node.retarget(cid, Retarget(north=new[0], east=new[1], altitude=-new[2]))
    f.wait_finished(cid, 30)
    f.wait_near(new, 1.0, 5)
    assert math.dist(f.pos(), far) > 20.0


def test_is_synced_while_following_the_stream_at_speed(f: FlightSession) -> None:
    """is_synced: the autopilot's echo is the streamed target advanced by its feed-forward (at 5 m/s)."""
    f.ensure_airborne()
    here = f.pos()
    (cid,) = f.add({"horizontal": {"mode": "POS", "north": here[0] + 45.0, "east": here[1], "speed": 5.0},
                    "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True}})
    wait_for(lambda: f.streamed and f.streamed[-1].command_id == cid and math.hypot(*f.streamed[-1].v) > 4.9,
             f.wall(8), "streaming at 5 m/s")
    samples: list[bool] = []
    t_end = f.sim_time() + 4.0
    while f.sim_time() < t_end:
        samples.append(f.status()["is_synced"])
        f.sim_wait(0.05)
    share = sum(samples) / len(samples)
    error = f.node.link.sync.last_error
    assert share >= 0.9, f"is_synced {share:.0%} of the time at 5 m/s (last error {error})"
    f.wait_finished(cid, 20)


def test_stop_then_reset_mid_flight(f: FlightSession) -> None:
    f.ensure_airborne()
    far = (f.pos()[0] + 40.0, f.pos()[1], -6.0)
    f.add({"horizontal": {"mode": "POS", "north": far[0], "east": far[1], "speed": 3.0},
           "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True}})
    wait_for(lambda: f.speed() > 2.0, f.wall(8), "flying north")
    assert f.post("/stop").status_code == 200
    st = f.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_status"] == "STOPPED"
    f.wait_still(8)
    stopped_at = f.pos()
    assert math.dist(stopped_at, far) > 20.0
    assert f.post("/run").status_code == 200  # resumes the stopped command
    wait_for(lambda: f.speed() > 2.0, f.wall(8), "flying north again")
    generation = f.status()["generation"]
    assert f.post("/reset").status_code == 200
    st = f.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_index"] == 0
    assert st["current_command_status"] == "UNKNOWN" and f.node.queue.commands == ()
    assert st["generation"] == generation + 1
    f.wait_still(8)
    hover = f.pos()
    f.sim_wait(2.0)
    assert math.dist(f.pos(), hover) < 0.8, "hovers where it is after reset"
    assert math.dist(hover, far) > 10.0
    assert f.phase() == "ENGAGED"


def test_bad_input_changes_nothing(f: FlightSession) -> None:
    before = (f.status(), f.node.queue.commands)
    cases = [
        ("/commands", {"horizontal": {"mode": "POS", "north": 1.0}, "end": {"e_h": True}}, 400, "east"),
        ("/commands", {"vertical": {"mode": "DNU"}, "end": {"e_v": True}}, 400, "e_v"),
        ("/commands", {"commands": [{"end": {"e_wait": 1}}, {"end": {}}]}, 400, "commands[1]"),
        ("/user_confirm", None, 409, "nothing is waiting"),
        ("/external/ext_vel", {"values": [1.0, 2.0], "validity_s": 0.5}, 400, "4 values"),
        ("/external/ext_vel", {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": -1}, 400, "validity"),
        ("/external/ext_vel", {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": 1e9}, 400, "maximum"),
        ("/external/no_such", {"values": [1.0]}, 400, "unknown stream"),
        ("/pause_direct", {"routine_id": "nope"}, 400, "unknown routine"),
    ]
    for path, body, code, text in cases:
        r = f.post(path, body)
        assert r.status_code == code, (path, r.text)
        assert text in r.json()["error"], r.json()
    r = f.http.post("/commands", content=b"{not json")
    assert r.status_code == 400 and "error" in r.json()
    after = (f.status(), f.node.queue.commands)
    assert after == before


def test_landing_with_allow_landing(f: FlightSession) -> None:
    f.ensure_airborne()
    here = f.pos()
    (cid,) = f.add(LAND_HERE)
    wait_for(lambda: f.node.link.mirror.snapshot().mode == LAND, f.wall(15), "LAND mode")
    wait_for(lambda: not f.armed(), f.wall(40), "landed and disarmed")
    f.wait_finished(cid, 5)
    assert math.dist(f.pos()[:2], here[:2]) < 1.5
    assert f.alt() < 0.5
    wait_for(lambda: f.phase() == "IDLE", f.wall(2), "link idle after the landing")


# --- verbs during a take-off: "stopped if allowed" (seed 000 Sec. V) ---------------------------------------
def test_stop_before_arming_arms_nothing(f: FlightSession) -> None:
    f.ensure_on_ground()
    setpoints = f.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    t0 = f.sim_time()
    (cid,) = f.add(TAKEOFF)
    f.node.run()
    f.node.stop()
    f.sim_wait(6.0)
    heard = f.heard_since(t0)
    assert heard and not heard[-1][1], "armed after a stop given before the take-off armed"
    assert max(h[2] for h in heard) < 0.3, "left the ground"
    assert f.tap.count("SET_POSITION_TARGET_LOCAL_NED") == setpoints
    st = f.status()
    assert (st["queue_status"], st["current_command_status"], st["current_command_id"]) == (
        "STOPPED", "STOPPED", cid)
    assert f.phase() == "IDLE"


def test_stop_once_armed_never_leaves_it_armed_near_the_ground(f: FlightSession) -> None:
    f.ensure_on_ground()
    f.add(TAKEOFF)
    f.node.run()
    wait_for(f.armed, f.wall(30), "armed by the take-off")
    f.node.stop()

    def settled() -> bool:  # disarmed on the ground, or holding at least a metre up
        return (not f.armed() and f.alt() < 0.3) or (f.armed() and f.alt() > 0.9 and f.speed() < 0.3)

    wait_for(settled, f.wall(20), "disarmed on the ground or holding above it")
    f.sim_wait(3.0)
    # (the speed of a GPS-grade estimate jitters by a few dm/s: judged on where it is, not how fast)
    assert (not f.armed() and f.alt() < 0.3) or (f.armed() and f.alt() > 0.9), \
        f"armed={f.armed()} at {f.alt():.2f} m"
    low = [h for h in f.heard_since(f.sim_time() - 3.0) if h[1] and h[2] < 0.5]
    assert not low, f"armed and {low[-1][2]:.2f} m up"


def test_stop_while_climbing_holds_above_the_ground(f: FlightSession) -> None:
    f.ensure_on_ground()
    f.add(TAKEOFF)
    f.node.run()
    wait_for(lambda: f.armed() and f.alt() > 0.3, f.wall(30), "climbing")
    f.node.stop()
    wait_for(lambda: f.status()["queue_status"] == "STOPPED" and f.speed() < 0.3 and f.alt() > 0.9,
             f.wall(20), "stopped and holding")
    held = f.alt()
    f.sim_wait(3.0)
    assert f.armed() and abs(f.alt() - held) < 0.5 and 0.9 < f.alt() < 5.0
    assert f.phase() == "ENGAGED"


def test_streamed_setpoints_are_continuous_on_the_wire(f: FlightSession) -> None:
    msgs = f.tap.kept()
    if len(msgs) < 200:
        pytest.skip("run with the flight tests before it: too few setpoints on the wire")
    violations = wire_violations(msgs, f.node.queue.limits)
    assert violations == [], violations[:5]


def test_override_by_gcs_stops_streaming(f: FlightSession) -> None:
    f.ensure_airborne()
    f.add({"horizontal": {"mode": "POS", "north": f.pos()[0] + 30.0, "east": f.pos()[1], "speed": 3.0},
           "vertical": {"mode": "POS", "altitude": 5.0}, "end": {"e_h": True}})
    wait_for(lambda: f.speed() > 2.0, f.wall(8), "flying north")
    assert f.gcs.set_mode(LOITER) == 0
    wait_for(lambda: f.status()["queue_system_status"] == "OVERRIDDEN", f.wall(2), "OVERRIDDEN")
    st = f.status()
    assert st["queue_status"] == "STOPPED" and not st["is_synced"]
    assert "LOITER" in (f.node.supervisor.override_reason or "")
    f.sim_wait(0.3)  # packets in flight
    count = f.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    f.sim_wait(3.0)
    assert f.tap.count("SET_POSITION_TARGET_LOCAL_NED") == count, "setpoints still sent after the override"
    assert f.node.link.mirror.snapshot().mode == LOITER
    # verbs that need the vehicle are refused while overridden
    assert f.post("/run").status_code == 409
    # the GCS gives the vehicle back: the override is lifted, the queue waits for run()
    assert f.gcs.set_mode(GUIDED) == 0
    wait_for(lambda: f.status()["queue_system_status"] == "RUNNING", f.wall(2), "override lifted")
    assert f.status()["queue_status"] == "STOPPED"


def test_disarm_by_someone_else_is_an_override(f: FlightSession) -> None:
    """A disarm we did not ask for (a GCS's forced disarm, a crash check) stops the stream too."""
    f.ensure_airborne()
    f.add({"end": {"e_user": True}})
    wait_for(lambda: f.phase() == "ENGAGED", f.wall(5), "engaged")
    # MAV_CMD_COMPONENT_ARM_DISARM 0 with the force code 21196: disarm in the air (the vehicle falls)
    assert f.gcs.command(400, 0, 21196) == 0
    wait_for(lambda: f.status()["queue_system_status"] == "OVERRIDDEN", f.wall(3), "OVERRIDDEN")
    assert f.node.supervisor.override_reason == "vehicle disarmed"
    count = f.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    f.sim_wait(2.0)
    assert f.tap.count("SET_POSITION_TARGET_LOCAL_NED") <= count + 1
    wait_for(lambda: f.alt() < 0.5, f.wall(20), "on the ground")
    assert f.gcs.set_mode(GUIDED) == 0  # given back: the next test can take off again
    wait_for(lambda: f.status()["queue_system_status"] == "RUNNING", f.wall(3), "override lifted")


def test_companion_loss_stops_within_guid_timeout(f: FlightSession) -> None:
    """ArduCopter (ModeGuided posvelaccel): without new targets the velocity and acceleration feed-forward
    are zeroed after GUID_TIMEOUT and the vehicle brakes and holds. Until then the last target's
    feed-forward is integrated, so a companion that dies while accelerating leaves the vehicle
    accelerating for up to GUID_TIMEOUT (ArduCopter's update_pos_vel_accel does the same).

    Judged on positions (the estimated speed of an outdoor GPS-grade estimate jitters by a few dm/s);
    "holds" from the moment it has been still for 2 s (ArduCopter settles back onto its frozen target)."""
    f.ensure_airborne()
    f.gcs.set_param("FS_GCS_ENABLE", 1)
    f.gcs.set_param("GUID_TIMEOUT", 3.0)
    f.add({"horizontal": {"mode": "POS", "north": f.pos()[0] + 40.0, "east": f.pos()[1], "speed": 3.0},
           "vertical": {"mode": "POS", "altitude": 5.0}, "end": {"e_h": True}})
    wait_for(lambda: f.speed() > 2.0, f.wall(10), "flying north")
    f.node.close()  # the companion dies mid-flight
    f.t_loss = f.sim_time()  # type: ignore[attr-defined]
    m0 = f.gcs.msg("LOCAL_POSITION_NED")
    p_loss, v_loss = (m0.x, m0.y), (m0.vx, m0.vy)
    track: list[tuple[float, tuple[float, float, float]]] = []

    def still_for(seconds: float) -> bool:
        m = f.gcs.msg("LOCAL_POSITION_NED")
        t = m.time_boot_ms / 1000.0
        if not track or t > track[-1][0]:
            track.append((t, (m.x, m.y, m.z)))
        recent = [s for s in track if s[0] >= t - seconds]
        return track[0][0] <= t - seconds and max(math.dist(s[1], track[-1][1]) for s in recent) < 0.3

    # GUID_TIMEOUT (3 s) with the feed-forward, then a jerk-limited stop from at most the envelope speed
    wait_for(lambda: still_for(2.0), f.wall(20.0), "still after GUID_TIMEOUT")
    t_stop, held = track[-1]
    # GUID_TIMEOUT, braking, 2 s of stillness; ArduCopter then settles back onto its frozen target
    assert t_stop - f.t_loss < 3.0 + 2.0 + 15.0  # type: ignore[attr-defined]
    # it stopped ahead of where it was at the loss, along its direction of motion
    ahead = (held[0] - p_loss[0]) * v_loss[0] + (held[1] - p_loss[1]) * v_loss[1]
    assert ahead > 0.0
    t = int((t_stop + 3.0) * 1000)
    wait_for(lambda: f.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, f.wall(4), "3 s")
    now = f.gcs.msg("LOCAL_POSITION_NED")
    assert math.dist((now.x, now.y, now.z), held) < 0.7, "holds where it stopped"


def test_gcs_failsafe_only_when_the_gcs_is_lost(f: FlightSession) -> None:
    """The companion's heartbeat is not a GCS heartbeat (ArduCopter counts system MAV_GCS_SYSID only):
    while the GCS is there nothing happens after the companion's loss; when the ground link goes too,
    FS_GCS_ENABLE's action (1: RTL) follows FS_GCS_TIMEOUT (5 s)."""
    if not hasattr(f, "t_loss"):
        f.ensure_airborne()
        f.gcs.set_param("FS_GCS_ENABLE", 1)
        f.node.close()
        f.t_loss = f.sim_time()  # type: ignore[attr-defined]
    t = int((f.t_loss + 8.0) * 1000)  # type: ignore[attr-defined]
    wait_for(lambda: f.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, f.wall(8), "8 s after the loss")
    assert f.gcs.mode() == GUIDED, "no failsafe while the GCS is connected"
    f.gcs.heartbeats.clear()
    wait_for(lambda: f.gcs.mode() == RTL, f.wall(5 + 3), "GCS failsafe RTL")
