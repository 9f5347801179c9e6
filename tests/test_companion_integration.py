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

import pytest

from companion.flight import Retarget
from harness.flight_session import LAND_HERE, TAKEOFF, FlightSession, SessionSpec
from harness.observer import GUIDED, LAND, LOITER, RTL
from harness.timing import wait_for
from harness.wire_tap import wire_violations

pytestmark = pytest.mark.integration

# 5x: the companion, the HTTP surface and the joystick feed run on the wall clock, so a slower
# autopilot leaves a loaded 2-core CI machine room to keep up
SPEEDUP = 5.0


FLIGHT_SESSION = SessionSpec("companion", SPEEDUP)


def test_takeoff(flight_session: FlightSession) -> None:
    flight_session.ensure_on_ground()
    r = flight_session.post("/commands", TAKEOFF)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["indices"] == [0] and len(body["ids"]) == 1
    assert flight_session.post("/run").status_code == 200
    wait_for(lambda: flight_session.phase() == "ENGAGED", flight_session.wall(30), "airborne")
    st = flight_session.status()
    assert st["queue_system_status"] == "RUNNING" and st["queue_status"] == "RUNNING"
    flight_session.wait_finished(body["ids"][0], 15)
    flight_session.wait_near((flight_session.pos()[0], flight_session.pos()[1], -5.0), 0.8, 10)
    snap = flight_session.node.link.mirror.snapshot()
    assert snap.mode == GUIDED and snap.armed
    assert flight_session.status()["current_command_status"] == "UNKNOWN"  # nothing after the take-off yet
    # the take-off was accepted the first time: no refusal, no second NAV_TAKEOFF
    assert not [e for e in flight_session.node.link.commands.errors if "TAKEOFF" in e], \
        list(flight_session.node.link.commands.errors)
    assert flight_session.tap.count("COMMAND_LONG") >= 3
    wait_for(lambda: flight_session.status()["is_synced"], flight_session.wall(3),
             "is_synced (POSITION_TARGET_LOCAL_NED echo)")


def test_three_waypoints_with_hor(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    wps = [(10.0, 0.0, 6.0), (10.0, 10.0, 8.0), (0.0, 10.0, 6.0)]
    ids = flight_session.add(*({"horizontal": {"mode": "POS", "north": n, "east": e},
                                "vertical": {"mode": "WITH_HOR", "altitude": alt}, "end": {"e_h": True,
                                                                                           "e_v": True}}
                               for n, e, alt in wps))
    for cid, (n, e, alt) in zip(ids, wps, strict=True):
        flight_session.wait_finished(cid, 30)
        # the command ends when the reference arrives; the vehicle is close behind
        flight_session.wait_near((n, e, -alt), 1.0, 5)
        assert flight_session.status()["queue_status"] == "RUNNING"
    flight_session.wait_near((0.0, 10.0, -6.0), 0.5, 5)


def test_heading_point(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    here = flight_session.pos()
    point = (here[0] - 20.0, here[1] + 20.0)  # south-east of the vehicle
    (cid,) = flight_session.add({"heading": {"mode": "POINT", "north": point[0], "east": point[1]},
                                 "end": {"e_hd": True}})
    flight_session.wait_finished(cid, 15)
    expected = math.atan2(point[1] - here[1], point[0] - here[0])
    wait_for(lambda: abs(math.remainder(flight_session.node.link.mirror.snapshot().yaw - expected,
                                        2 * math.pi))
             < math.radians(8), flight_session.wall(5), "yaw towards the point")
    assert math.dist(flight_session.pos()[:2], here[:2]) < 1.0


def test_wait(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    here = flight_session.pos()
    t0 = flight_session.sim_time()
    (cid,) = flight_session.add({"end": {"e_wait": 3.0}})
    flight_session.wait_finished(cid, 10)
    # two ticks of slack: the test reads its estimate of the autopilot clock between the node's ticks
    assert flight_session.sim_time() - t0 >= 3.0 - 0.1
    assert math.dist(flight_session.pos(), here) < 1.0


def test_joystick_ext_vel_until_user_confirm(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    (cid,) = flight_session.add({"horizontal": {"mode": "EXT_VEL"}, "vertical": {"mode": "EXT_VEL"},
                                 "heading": {"mode": "EXT_VEL"}, "end": {"e_user": True}})
    wait_for(lambda: flight_session.status()["confirmation_required_status"], flight_session.wall(3),
             "confirmation required")
    start = flight_session.pos()
    # 3 m at 1.5 m/s take 2 s plus the ramp; a loaded machine ticks late
    t_end = flight_session.sim_time() + 8.0
    while flight_session.sim_time() < t_end and flight_session.pos()[0] - start[0] <= 3.0:
        # a joystick pushing north at 1.5 m/s, 10 Hz of simulated time; validity 2 s: a late HTTP round
        # trip on a busy machine must not let the sample go stale (the stale -> zero-velocity behavior
        # is the flight layer's unit tests' business)
        r = flight_session.post("/external/ext_vel", {"values": [1.5, 0.0, 0.0, 0.0], "validity_s": 2.0})
        assert r.status_code == 200, r.text
        flight_session.sim_wait(0.1)
    moved = flight_session.pos()[0] - start[0]
    assert moved > 3.0, f"the joystick moved the vehicle only {moved:.2f} m north in 8 s"
    assert abs(flight_session.pos()[1] - start[1]) < 1.0  # and north only
    velocity_only = [m for m in flight_session.tap.kept() if m.type_mask & 0b111]
    assert velocity_only, "no velocity-only SET_POSITION_TARGET_LOCAL_NED on the wire"
    assert flight_session.post("/user_confirm").status_code == 200
    flight_session.wait_finished(cid, 3)
    flight_session.wait_still(6)  # the stream went stale / the next command holds: it stops


def test_pause_direct_then_run(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    here = flight_session.pos()
    target = (here[0], here[1] + 40.0, -6.0)  # 13 s at 3 m/s: paused mid-way even after a late poll
    (cid,) = flight_session.add({"horizontal": {"mode": "POS", "north": target[0], "east": target[1],
                                                "speed": 3.0},
                                 "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True,
                                                                                       "e_v": True}})
    wait_for(lambda: flight_session.speed() > 2.0, flight_session.wall(8), "flying east")
    assert flight_session.post("/pause_direct").status_code == 200
    st = flight_session.status()
    assert st["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING"
    assert st["current_command_status"] == "PAUSED" and st["current_command_id"] == cid
    assert st["confirmation_required_status"]  # the hover routine ends on user_confirm
    flight_session.wait_still(8)
    paused_at = flight_session.pos()
    assert math.dist(paused_at, target) > 5.0
    flight_session.sim_wait(2.0)
    assert math.dist(flight_session.pos(), paused_at) < 0.8, "holds while paused"
    assert flight_session.post("/run").status_code == 200
    assert flight_session.status()["current_command_status"] == "RUNNING"
    flight_session.wait_finished(cid, 30)
    flight_session.wait_near(target, 1.0, 5)


def test_pause_after_current(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    a = (flight_session.pos()[0] - 10.0, flight_session.pos()[1], -6.0)
    b = (a[0], a[1] - 10.0, -6.0)
    ida, idb = flight_session.add(*({"horizontal": {"mode": "POS", "north": n, "east": e},
                                     "vertical": {"mode": "POS", "altitude": -d}, "end": {"e_h": True,
                                                                                          "e_v": True}}
                                    for n, e, d in (a, b)))
    wait_for(lambda: flight_session.speed() > 1.0, flight_session.wall(5), "flying to A")
    assert flight_session.post("/pause_after_current", {"routine_id": "hover"}).status_code == 200
    assert flight_session.status()["queue_status"] == "RUNNING"  # still flying the current command
    flight_session.wait_finished(ida, 15)
    wait_for(lambda: flight_session.status()["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING",
             flight_session.wall(2), "pause")
    st = flight_session.status()
    assert st["current_command_id"] == idb and st["current_command_status"] == "PAUSED"
    flight_session.wait_near(a, 1.0, 5)
    flight_session.wait_still(5)
    held = flight_session.pos()
    flight_session.sim_wait(2.0)
    # held on the (GPS-grade) estimate: decimetres of jitter, no drift
    assert math.dist(flight_session.pos(),
                     held) < 0.8 and flight_session.status()["current_command_id"] == idb
    assert flight_session.post("/user_confirm").status_code == 200  # ends the hover routine: on to B
    flight_session.wait_finished(idb, 20)
    flight_session.wait_near(b, 1.0, 5)


def test_retarget_in_flight(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    here = flight_session.pos()
    far = (here[0] + 40.0, here[1], -6.0)
    (cid,) = flight_session.add({"horizontal": {"mode": "POS", "north": far[0], "east": far[1], "speed": 4.0},
                                 "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True,
                                                                                       "e_v": True}})
    wait_for(lambda: flight_session.speed() > 3.0, flight_session.wall(8), "flying north")
    new = (here[0] + 10.0, here[1] + 10.0, -7.0)
    flight_session.node.retarget(cid, Retarget(north=new[0], east=new[1], altitude=-new[2]))
    flight_session.wait_finished(cid, 30)
    flight_session.wait_near(new, 1.0, 5)
    assert math.dist(flight_session.pos(), far) > 20.0


def test_is_synced_while_following_the_stream_at_speed(flight_session: FlightSession) -> None:
    """is_synced: the autopilot's echo is the streamed target advanced by its feed-forward (at 5 m/s)."""
    flight_session.ensure_airborne()
    here = flight_session.pos()
    (cid,) = flight_session.add({"horizontal": {"mode": "POS", "north": here[0] + 45.0, "east": here[1],
                                                "speed": 5.0},
                                 "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True}})
    wait_for(lambda: flight_session.streamed and flight_session.streamed[-1].command_id == cid
             and math.hypot(*flight_session.streamed[-1].v) > 4.9, flight_session.wall(8),
             "streaming at 5 m/s")
    samples: list[bool] = []
    t_end = flight_session.sim_time() + 4.0
    while flight_session.sim_time() < t_end:
        samples.append(flight_session.status()["is_synced"])
        flight_session.sim_wait(0.05)
    share = sum(samples) / len(samples)
    error = flight_session.node.link.sync.last_error
    assert share >= 0.9, f"is_synced {share:.0%} of the time at 5 m/s (last error {error})"
    flight_session.wait_finished(cid, 20)


def test_stop_then_reset_mid_flight(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    far = (flight_session.pos()[0] + 40.0, flight_session.pos()[1], -6.0)
    flight_session.add({"horizontal": {"mode": "POS", "north": far[0], "east": far[1], "speed": 3.0},
                        "vertical": {"mode": "POS", "altitude": 6.0}, "end": {"e_h": True}})
    wait_for(lambda: flight_session.speed() > 2.0, flight_session.wall(8), "flying north")
    assert flight_session.post("/stop").status_code == 200
    st = flight_session.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_status"] == "STOPPED"
    flight_session.wait_still(8)
    stopped_at = flight_session.pos()
    assert math.dist(stopped_at, far) > 20.0
    assert flight_session.post("/run").status_code == 200  # resumes the stopped command
    wait_for(lambda: flight_session.speed() > 2.0, flight_session.wall(8), "flying north again")
    generation = flight_session.status()["generation"]
    assert flight_session.post("/reset").status_code == 200
    st = flight_session.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_index"] == 0
    assert st["current_command_status"] == "UNKNOWN" and flight_session.node.queue.commands == ()
    assert st["generation"] == generation + 1
    flight_session.wait_still(8)
    hover = flight_session.pos()
    flight_session.sim_wait(2.0)
    assert math.dist(flight_session.pos(), hover) < 0.8, "hovers where it is after reset"
    assert math.dist(hover, far) > 10.0
    assert flight_session.phase() == "ENGAGED"


def test_bad_input_changes_nothing(flight_session: FlightSession) -> None:
    before = (flight_session.status(), flight_session.node.queue.commands)
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
        r = flight_session.post(path, body)
        assert r.status_code == code, (path, r.text)
        assert text in r.json()["error"], r.json()
    r = flight_session.http.post("/commands", content=b"{not json")
    assert r.status_code == 400 and "error" in r.json()
    after = (flight_session.status(), flight_session.node.queue.commands)
    assert after == before


def test_landing_with_allow_landing(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    here = flight_session.pos()
    (cid,) = flight_session.add(LAND_HERE)
    wait_for(lambda: flight_session.node.link.mirror.snapshot().mode == LAND, flight_session.wall(15),
             "LAND mode")
    wait_for(lambda: not flight_session.armed(), flight_session.wall(40), "landed and disarmed")
    flight_session.wait_finished(cid, 5)
    assert math.dist(flight_session.pos()[:2], here[:2]) < 1.5
    assert flight_session.alt() < 0.5
    wait_for(lambda: flight_session.phase() == "IDLE", flight_session.wall(2), "link idle after the landing")


# --- verbs during a take-off: "stopped if allowed" (seed 000 Sec. V) ---------------------------------------
def test_stop_before_arming_arms_nothing(flight_session: FlightSession) -> None:
    flight_session.ensure_on_ground()
    setpoints = flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    t0 = flight_session.sim_time()
    (cid,) = flight_session.add(TAKEOFF)
    flight_session.node.run()
    flight_session.node.stop()
    flight_session.sim_wait(6.0)
    heard = flight_session.heard_since(t0)
    assert heard and not heard[-1][1], "armed after a stop given before the take-off armed"
    assert max(h[2] for h in heard) < 0.3, "left the ground"
    assert flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED") == setpoints
    st = flight_session.status()
    assert (st["queue_status"], st["current_command_status"], st["current_command_id"]) == (
        "STOPPED", "STOPPED", cid)
    assert flight_session.phase() == "IDLE"


def test_stop_once_armed_never_leaves_it_armed_near_the_ground(flight_session: FlightSession) -> None:
    flight_session.ensure_on_ground()
    flight_session.add(TAKEOFF)
    flight_session.node.run()
    wait_for(flight_session.armed, flight_session.wall(30), "armed by the take-off")
    flight_session.node.stop()

    def settled() -> bool:  # disarmed on the ground, or holding at least a metre up
        return (not flight_session.armed() and flight_session.alt() < 0.3) or \
            (flight_session.armed() and flight_session.alt() > 0.9 and flight_session.speed() < 0.3)

    wait_for(settled, flight_session.wall(20), "disarmed on the ground or holding above it")
    flight_session.sim_wait(3.0)
    # (the speed of a GPS-grade estimate jitters by a few dm/s: judged on where it is, not how fast)
    assert (not flight_session.armed() and flight_session.alt() < 0.3) or \
        (flight_session.armed() and flight_session.alt() > 0.9), \
        f"armed={flight_session.armed()} at {flight_session.alt():.2f} m"
    low = [h for h in flight_session.heard_since(flight_session.sim_time() - 3.0) if h[1] and h[2] < 0.5]
    assert not low, f"armed and {low[-1][2]:.2f} m up"


def test_stop_while_climbing_holds_above_the_ground(flight_session: FlightSession) -> None:
    flight_session.ensure_on_ground()
    flight_session.add(TAKEOFF)
    flight_session.node.run()
    wait_for(lambda: flight_session.armed() and flight_session.alt() > 0.3, flight_session.wall(30),
             "climbing")
    flight_session.node.stop()
    wait_for(lambda: flight_session.status()["queue_status"] == "STOPPED" and flight_session.speed() < 0.3
             and flight_session.alt() > 0.9, flight_session.wall(20), "stopped and holding")
    held = flight_session.alt()
    flight_session.sim_wait(3.0)
    assert flight_session.armed() and abs(flight_session.alt() - held) < 0.5 \
        and 0.9 < flight_session.alt() < 5.0
    assert flight_session.phase() == "ENGAGED"


def test_streamed_setpoints_are_continuous_on_the_wire(flight_session: FlightSession) -> None:
    msgs = flight_session.tap.kept()
    if len(msgs) < 200:
        pytest.skip("run with the flight tests before it: too few setpoints on the wire")
    violations = wire_violations(msgs, flight_session.node.queue.limits)
    assert violations == [], violations[:5]


def test_override_by_gcs_stops_streaming(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    flight_session.add({"horizontal": {"mode": "POS", "north": flight_session.pos()[0] + 30.0,
                                       "east": flight_session.pos()[1], "speed": 3.0},
                        "vertical": {"mode": "POS", "altitude": 5.0}, "end": {"e_h": True}})
    wait_for(lambda: flight_session.speed() > 2.0, flight_session.wall(8), "flying north")
    assert flight_session.gcs.set_mode(LOITER) == 0
    wait_for(lambda: flight_session.status()["queue_system_status"] == "OVERRIDDEN", flight_session.wall(2),
             "OVERRIDDEN")
    st = flight_session.status()
    assert st["queue_status"] == "STOPPED" and not st["is_synced"]
    assert "LOITER" in (flight_session.node.supervisor.override_reason or "")
    flight_session.sim_wait(0.3)  # packets in flight
    count = flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    flight_session.sim_wait(3.0)
    assert flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED") == count, \
        "setpoints still sent after the override"
    assert flight_session.node.link.mirror.snapshot().mode == LOITER
    # verbs that need the vehicle are refused while overridden
    assert flight_session.post("/run").status_code == 409
    # the GCS gives the vehicle back: the override is lifted, the queue waits for run()
    assert flight_session.gcs.set_mode(GUIDED) == 0
    wait_for(lambda: flight_session.status()["queue_system_status"] == "RUNNING", flight_session.wall(2),
             "override lifted")
    assert flight_session.status()["queue_status"] == "STOPPED"


def test_disarm_by_someone_else_is_an_override(flight_session: FlightSession) -> None:
    """A disarm we did not ask for (a GCS's forced disarm, a crash check) stops the stream too."""
    flight_session.ensure_airborne()
    flight_session.add({"end": {"e_user": True}})
    wait_for(lambda: flight_session.phase() == "ENGAGED", flight_session.wall(5), "engaged")
    # MAV_CMD_COMPONENT_ARM_DISARM 0 with the force code 21196: disarm in the air (the vehicle falls)
    assert flight_session.gcs.command(400, 0, 21196) == 0
    wait_for(lambda: flight_session.status()["queue_system_status"] == "OVERRIDDEN", flight_session.wall(3),
             "OVERRIDDEN")
    assert flight_session.node.supervisor.override_reason == "vehicle disarmed"
    count = flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    flight_session.sim_wait(2.0)
    assert flight_session.tap.count("SET_POSITION_TARGET_LOCAL_NED") <= count + 1
    wait_for(lambda: flight_session.alt() < 0.5, flight_session.wall(20), "on the ground")
    assert flight_session.gcs.set_mode(GUIDED) == 0  # given back: the next test can take off again
    wait_for(lambda: flight_session.status()["queue_system_status"] == "RUNNING", flight_session.wall(3),
             "override lifted")


def test_companion_loss_stops_within_guid_timeout(flight_session: FlightSession) -> None:
    """ArduCopter (ModeGuided posvelaccel): without new targets the velocity and acceleration feed-forward
    are zeroed after GUID_TIMEOUT and the vehicle brakes and holds. Until then the last target's
    feed-forward is integrated, so a companion that dies while accelerating leaves the vehicle
    accelerating for up to GUID_TIMEOUT (ArduCopter's update_pos_vel_accel does the same).

    Judged on positions (the estimated speed of an outdoor GPS-grade estimate jitters by a few dm/s);
    "holds" from the moment it has been still for 2 s (ArduCopter settles back onto its frozen target)."""
    flight_session.ensure_airborne()
    flight_session.gcs.set_param("FS_GCS_ENABLE", 1)
    flight_session.gcs.set_param("GUID_TIMEOUT", 3.0)
    flight_session.add({"horizontal": {"mode": "POS", "north": flight_session.pos()[0] + 40.0,
                                       "east": flight_session.pos()[1], "speed": 3.0},
                        "vertical": {"mode": "POS", "altitude": 5.0}, "end": {"e_h": True}})
    wait_for(lambda: flight_session.speed() > 2.0, flight_session.wall(10), "flying north")
    flight_session.node.close()  # the companion dies mid-flight
    flight_session.t_loss = flight_session.sim_time()  # type: ignore[attr-defined]
    m0 = flight_session.gcs.msg("LOCAL_POSITION_NED")
    p_loss, v_loss = (m0.x, m0.y), (m0.vx, m0.vy)
    track: list[tuple[float, tuple[float, float, float]]] = []

    def still_for(seconds: float) -> bool:
        m = flight_session.gcs.msg("LOCAL_POSITION_NED")
        t = m.time_boot_ms / 1000.0
        if not track or t > track[-1][0]:
            track.append((t, (m.x, m.y, m.z)))
        recent = [s for s in track if s[0] >= t - seconds]
        return track[0][0] <= t - seconds and max(math.dist(s[1], track[-1][1]) for s in recent) < 0.3

    # GUID_TIMEOUT (3 s) with the feed-forward, then a jerk-limited stop from at most the envelope speed
    wait_for(lambda: still_for(2.0), flight_session.wall(20.0), "still after GUID_TIMEOUT")
    t_stop, held = track[-1]
    # GUID_TIMEOUT, braking, 2 s of stillness; ArduCopter then settles back onto its frozen target
    assert t_stop - flight_session.t_loss < 3.0 + 2.0 + 15.0  # type: ignore[attr-defined]
    # it stopped ahead of where it was at the loss, along its direction of motion
    ahead = (held[0] - p_loss[0]) * v_loss[0] + (held[1] - p_loss[1]) * v_loss[1]
    assert ahead > 0.0
    t = int((t_stop + 3.0) * 1000)
    wait_for(lambda: flight_session.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, flight_session.wall(4),
             "3 s")
    now = flight_session.gcs.msg("LOCAL_POSITION_NED")
    assert math.dist((now.x, now.y, now.z), held) < 0.7, "holds where it stopped"


def test_gcs_failsafe_only_when_the_gcs_is_lost(flight_session: FlightSession) -> None:
    """The companion's heartbeat is not a GCS heartbeat (ArduCopter counts system MAV_GCS_SYSID only):
    while the GCS is there nothing happens after the companion's loss; when the ground link goes too,
    FS_GCS_ENABLE's action (1: RTL) follows FS_GCS_TIMEOUT (5 s)."""
    if not hasattr(flight_session, "t_loss"):
        flight_session.ensure_airborne()
        flight_session.gcs.set_param("FS_GCS_ENABLE", 1)
        flight_session.node.close()
        flight_session.t_loss = flight_session.sim_time()  # type: ignore[attr-defined]
    t = int((flight_session.t_loss + 8.0) * 1000)  # type: ignore[attr-defined]
    wait_for(lambda: flight_session.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, flight_session.wall(8),
             "8 s after the loss")
    assert flight_session.gcs.mode() == GUIDED, "no failsafe while the GCS is connected"
    flight_session.gcs.heartbeats.clear()
    wait_for(lambda: flight_session.gcs.mode() == RTL, flight_session.wall(5 + 3), "GCS failsafe RTL")
