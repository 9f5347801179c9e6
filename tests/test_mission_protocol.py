"""State-machine tests of the vehicle side of the MAVLink mission protocol, with a fake endpoint."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.mavlink.mission_protocol import ITEM_TIMEOUT_S, MAX_RETRIES, MissionProtocol
from autopilot_model.modules.mission import FENCE, MISSION, MissionItem, MissionStore

HOME = (47.397742, 8.545594, 488.0)


class FakeEndpoint:
    """Captures what the protocol sends; delivers messages as if they came from a GCS."""

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.handlers: dict[str, Any] = {}
        self.sent: list[Any] = []
        self.texts: list[str] = []

    def add_handler(self, msg_type: str, fn: Any) -> None:
        self.handlers[msg_type] = fn

    def send(self, msg: Any, link: Any = None) -> None:
        self.sent.append(msg)

    def statustext(self, severity: int, text: str) -> None:
        self.texts.append(text)

    def deliver(self, msg: Any, sysid: int = 255, compid: int = 190) -> None:
        msg.pack(mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid))
        self.handlers[msg.get_type()](msg, "link")

    def take(self, msg_type: str | None = None) -> list[Any]:
        out = [m for m in self.sent if msg_type is None or m.get_type() == msg_type]
        self.sent = [m for m in self.sent if m not in out]
        return out


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t


@pytest.fixture
def env(tmp_path):
    ep, clock = FakeEndpoint(), Clock()
    store = MissionStore(tmp_path / "mission.json")
    proto = MissionProtocol(ep, store, now=clock.now, home=lambda: HOME)
    return ep, clock, store, proto


def gcs() -> mavlink.MAVLink:
    return mavlink.MAVLink(None, srcSystem=255, srcComponent=190)


def wp(seq: int, lat: float, lon: float, alt: float, cmd: int = mavlink.MAV_CMD_NAV_WAYPOINT,
       frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mtype: int = MISSION,
       p1: float = 0.0) -> Any:
    return gcs().mission_item_int_encode(1, 1, seq, frame, cmd, 0, 1, p1, 0, 0, 0,
                                         round(lat * 1e7), round(lon * 1e7), alt, mtype)


def plan() -> list[Any]:
    return [wp(0, *HOME[:2], HOME[2], frame=mavlink.MAV_FRAME_GLOBAL),
            wp(1, 0, 0, 10, cmd=mavlink.MAV_CMD_NAV_TAKEOFF),
            wp(2, HOME[0] + 1e-4, HOME[1], 10),
            wp(3, 0, 0, 0, cmd=mavlink.MAV_CMD_NAV_LAND)]


def upload(ep: FakeEndpoint, items: list[Any], mtype: int = MISSION) -> Any:
    ep.deliver(gcs().mission_count_encode(1, 1, len(items), mtype))
    acks: list[Any] = []
    for it in items:
        reqs = ep.take("MISSION_REQUEST_INT")
        assert [r.seq for r in reqs] == [it.seq]
        ep.deliver(it)
        acks = ep.take("MISSION_ACK")
        if acks:
            break
    assert len(acks) == 1
    return acks[0]


def test_upload_then_download_equal(env):
    ep, _, store, _ = env
    items = plan()
    assert upload(ep, items).type == mavlink.MAV_MISSION_ACCEPTED
    assert store.count() == 4
    ep.take()
    ep.deliver(gcs().mission_request_list_encode(1, 1, MISSION))
    assert ep.take("MISSION_COUNT")[0].count == 4
    for seq, sent in enumerate(items):
        ep.deliver(gcs().mission_request_int_encode(1, 1, seq, MISSION))
        got = ep.take("MISSION_ITEM_INT")[0]
        for f in ("seq", "frame", "command", "autocontinue", "param1", "param2", "x", "y", "z"):
            assert getattr(got, f) == getattr(sent, f), (seq, f)


def test_legacy_request_answered_with_item_int_and_legacy_item_accepted(env):
    ep, _, store, _ = env
    ep.deliver(gcs().mission_count_encode(1, 1, 2, MISSION))
    ep.deliver(gcs().mission_item_encode(1, 1, 0, mavlink.MAV_FRAME_GLOBAL, 16, 0, 1, 0, 0, 0, 0,
                                         HOME[0], HOME[1], HOME[2], MISSION))
    ep.deliver(gcs().mission_item_encode(1, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 0, 1, 0, 0,
                                         0, 0, 47.3987, 8.5461, 12.5, MISSION))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    assert store.item(1).x == 473987000 and store.item(1).y == 85461000
    ep.deliver(gcs().mission_request_encode(1, 1, 1, MISSION))
    got = ep.take("MISSION_ITEM_INT")
    assert len(got) == 1 and got[0].x == 473987000 and got[0].z == 12.5


def test_failed_upload_leaves_mission_unchanged(env):
    ep, _, store, _ = env
    upload(ep, plan())
    before = store.items
    # unsupported command in item 2
    bad = plan()
    bad[2] = wp(2, HOME[0], HOME[1], 10, cmd=mavlink.MAV_CMD_DO_SET_SERVO)
    assert upload(ep, bad).type == mavlink.MAV_MISSION_UNSUPPORTED
    # infinite parameter / out-of-range latitude / unsupported frame / NaN altitude
    cases = [
        (gcs().mission_item_int_encode(1, 1, 1, 6, 16, 0, 1, math.inf, 0, 0, 0, 1, 1, 10, 0),
         mavlink.MAV_MISSION_INVALID_PARAM1),
        (gcs().mission_item_int_encode(1, 1, 1, 6, 16, 0, 1, 0, 0, 0, 0, 950_000_000, 1, 10, 0),
         mavlink.MAV_MISSION_INVALID_PARAM5_X),
        (gcs().mission_item_int_encode(1, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 16, 0, 1, 0, 0, 0, 0, 1, 1,
                                       10, 0), mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        (gcs().mission_item_int_encode(1, 1, 1, 6, 16, 0, 1, 0, 0, 0, 0, 1, 1, math.nan, 0),
         mavlink.MAV_MISSION_INVALID_PARAM7),
        (gcs().mission_item_int_encode(1, 1, 1, 6, 16, 0, 1, -1, 0, 0, 0, 1, 1, 10, 0),
         mavlink.MAV_MISSION_INVALID_PARAM1),
    ]
    for item, code in cases:
        items = plan()
        items[1] = item
        assert upload(ep, items[:2]).type == code
    assert store.items == before


def test_nan_yaw_is_accepted(env):
    ep, _, store, _ = env
    items = plan()
    items[2] = gcs().mission_item_int_encode(1, 1, 2, 6, 16, 0, 1, 0, 0, 0, math.nan, 473987000,
                                             85461000, 10, 0)
    assert upload(ep, items).type == mavlink.MAV_MISSION_ACCEPTED
    assert math.isnan(store.item(2).param4)


def test_wrong_sequence_and_unknown_mission_type(env):
    ep, _, store, _ = env
    ep.deliver(gcs().mission_count_encode(1, 1, 3, MISSION))
    ep.take()
    ep.deliver(wp(5, *HOME[:2], 10))  # out of range
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    ep.deliver(gcs().mission_count_encode(1, 1, 2, 7))  # no such mission type
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_UNSUPPORTED
    ep.deliver(gcs().mission_request_list_encode(1, 1, 9))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_UNSUPPORTED
    ep.deliver(gcs().mission_request_int_encode(1, 1, 0, MISSION))  # empty store
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    assert store.count() == 0


def test_item_outside_an_upload_and_other_peer_denied(env):
    ep, _, _, _ = env
    ep.deliver(wp(0, *HOME[:2], 10))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ERROR
    ep.deliver(gcs().mission_count_encode(1, 1, 2, MISSION))
    ep.take()
    other = mavlink.MAVLink(None, srcSystem=254, srcComponent=1).mission_count_encode(1, 1, 2, MISSION)
    ep.deliver(other, sysid=254, compid=1)
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_DENIED


def test_retries_then_cancel(env):
    ep, clock, store, proto = env
    ep.deliver(gcs().mission_count_encode(1, 1, 2, MISSION))
    assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [0]
    ep.deliver(plan()[0])
    ep.take()
    for _ in range(MAX_RETRIES):
        clock.t += ITEM_TIMEOUT_S / 2
        proto.periodic()
        assert ep.take("MISSION_REQUEST_INT") == []
        clock.t += ITEM_TIMEOUT_S / 2 + 0.01
        proto.periodic()
        assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [1]
    # a late answer to a repeated request still completes... but not after giving up:
    clock.t += ITEM_TIMEOUT_S + 0.01
    proto.periodic()
    acks = ep.take("MISSION_ACK")
    assert [a.type for a in acks] == [mavlink.MAV_MISSION_OPERATION_CANCELLED]
    assert not proto.uploading and store.count() == 0


def test_timeouts_count_simulated_time_only(env, monkeypatch):
    """As in ArduCopter SITL (``AP_HAL::millis()`` is simulated time), the request is
    repeated and the upload given up on simulated time, whatever the wall does: a sped-up model (the wall
    stands still while simulated time passes) times out, a paused one (the wall runs on) does not."""
    ep, clock, _, proto = env
    wall = [1000.0]
    monkeypatch.setattr("time.monotonic", lambda: wall[0])
    monkeypatch.setattr("time.time", lambda: wall[0])
    ep.deliver(gcs().mission_count_encode(1, 1, 2, MISSION))
    assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [0]
    wall[0] += 60.0  # a paused simulation: only the wall runs
    proto.periodic()
    assert ep.take() == []
    for _ in range(MAX_RETRIES):  # a sped-up simulation: only simulated time runs
        clock.t += ITEM_TIMEOUT_S + 0.01
        proto.periodic()
        assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [0]
    clock.t += ITEM_TIMEOUT_S + 0.01
    proto.periodic()
    assert [a.type for a in ep.take("MISSION_ACK")] == [mavlink.MAV_MISSION_OPERATION_CANCELLED]
    assert not proto.uploading


def test_duplicate_item_rerequests_and_lost_final_ack_repeated(env):
    ep, _, store, _ = env
    items = plan()
    ep.deliver(gcs().mission_count_encode(1, 1, 4, MISSION))
    ep.take()
    ep.deliver(items[0])
    ep.deliver(items[0])  # duplicate: ask again for 1
    assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [1, 1]
    for it in items[1:]:
        ep.deliver(it)
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    ep.deliver(items[3])  # GCS did not get the ACK and sends the last item again
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    assert store.count() == 4


def test_clear_set_current_and_persistence(env, tmp_path):
    ep, _, store, _ = env
    upload(ep, plan())
    ep.take()
    ep.deliver(gcs().mission_set_current_encode(1, 1, 2))
    cur = ep.take("MISSION_CURRENT")
    assert cur and cur[-1].seq == 2 and cur[-1].total == 3
    ep.deliver(gcs().mission_set_current_encode(1, 1, 9))
    assert ep.take("MISSION_CURRENT")[-1].seq == 2 and ep.texts
    again = MissionStore(tmp_path / "mission.json")
    assert again.items == store.items and again.current == 2
    store.running = True
    ep.deliver(gcs().mission_clear_all_encode(1, 1, MISSION))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_DENIED
    store.running = False
    ep.deliver(gcs().mission_clear_all_encode(1, 1, MISSION))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    assert store.count() == 0 and MissionStore(tmp_path / "mission.json").count() == 0


def test_fence_polygon_upload_kept_separately(env):
    ep, _, store, _ = env
    upload(ep, plan())
    inc = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    corners = [(47.3970, 8.5440), (47.3990, 8.5440), (47.3990, 8.5470), (47.3970, 8.5470)]
    fence = [wp(i, lat, lon, 0, cmd=inc, frame=mavlink.MAV_FRAME_GLOBAL_INT, mtype=FENCE, p1=4)
             for i, (lat, lon) in enumerate(corners)]
    assert upload(ep, fence, FENCE).type == mavlink.MAV_MISSION_ACCEPTED
    assert store.count(FENCE) == 4 and store.count(MISSION) == 4
    # a polygon whose vertex count does not match its items is refused whole
    assert upload(ep, fence[:3], FENCE).type == mavlink.MAV_MISSION_INVALID_PARAM1
    assert store.count(FENCE) == 4


def test_download_item0_is_home(env):
    ep, _, _, _ = env
    items = plan()
    items[0] = wp(0, 1.0, 2.0, 3.0, frame=mavlink.MAV_FRAME_GLOBAL)
    upload(ep, items)
    ep.deliver(gcs().mission_request_int_encode(1, 1, 0, MISSION))
    got = ep.take("MISSION_ITEM_INT")[0]
    assert (got.x, got.y, got.z) == (round(HOME[0] * 1e7), round(HOME[1] * 1e7), HOME[2])


def test_mission_item_roundtrip_dict():
    it = MissionItem(seq=3, frame=6, command=16, param4=math.nan, x=1, y=2, z=3.5)
    back = MissionItem.from_dict(it.to_dict())
    assert back.seq == 3 and math.isnan(back.param4)


def test_write_partial_list_replaces_a_range_and_appends(env):
    """MISSION_WRITE_PARTIAL_LIST as ArduPilot's MissionItemProtocol: items start..end requested in turn,
    the others kept; end = count appends; a bad range is MAV_MISSION_ERROR; busy is DENIED."""
    ep, _, store, _ = env
    assert upload(ep, plan()).type == mavlink.MAV_MISSION_ACCEPTED
    ep.take()
    ep.deliver(gcs().mission_write_partial_list_encode(1, 1, 2, 2, MISSION))
    assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [2]
    ep.deliver(gcs().mission_write_partial_list_encode(1, 1, 1, 1, MISSION))  # busy with the first one
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_DENIED
    ep.deliver(wp(2, HOME[0] + 2e-4, HOME[1], 25, p1=4))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    items = store.items
    assert len(items) == 4 and items[2].z == 25 and items[2].param1 == 4
    assert items[1].command == mavlink.MAV_CMD_NAV_TAKEOFF and items[3].command == mavlink.MAV_CMD_NAV_LAND
    ep.deliver(gcs().mission_write_partial_list_encode(1, 1, 4, 4, MISSION))  # append
    assert [r.seq for r in ep.take("MISSION_REQUEST_INT")] == [4]
    ep.deliver(wp(4, HOME[0], HOME[1], 5))
    assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ACCEPTED
    assert store.count() == 5
    for start, end in ((3, 2), (6, 6), (0, 9)):
        ep.deliver(gcs().mission_write_partial_list_encode(1, 1, start, end, MISSION))
        assert ep.take("MISSION_ACK")[0].type == mavlink.MAV_MISSION_ERROR, (start, end)
    assert store.count() == 5


def test_do_jump_must_name_an_item_of_the_plan(env):
    ep, _, store, _ = env
    items = [*plan()[:3], wp(3, 0, 0, 0, cmd=mavlink.MAV_CMD_DO_JUMP, p1=7)]
    assert upload(ep, items).type == mavlink.MAV_MISSION_ERROR
    assert store.count() == 0
    items[3] = wp(3, 0, 0, 0, cmd=mavlink.MAV_CMD_DO_JUMP, p1=2)
    assert upload(ep, items).type == mavlink.MAV_MISSION_ACCEPTED
