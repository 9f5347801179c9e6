"""One chain of command in the companion (seed 001 Definition 3, Fig. 6-7): the coordinator is the queue's
one writer, the operator outranks the mission, requesters come from credentials.

* credentials (no flight; a companion whose autopilot never answers, its control surface on loopback):
  a mission token cannot request as operator or emergency (403), an observer token cannot write (403), the
  operator's can; the flight-command path is the FLY_COMMANDS behavior of the caller's requester, a lower
  requester can neither replace nor pause nor stop it (409 naming the holder); no tokens + a non-loopback
  host is refused; the ground service refuses a tokens file with a role it does not take, naming it;
* the coordinator (the kinematic world of :mod:`harness.behaviors`): the operator's assistance pause
  suspends the mission's GO_TO_POINT (which then gets there once confirmed) and keeps every mission
  maneuver out; a mission node refused during a break-in fails with the coordinator's reason; FLY_COMMANDS
  held until ``run``, appended to, every command FINISHED, the default hover only afterwards;
* ``--commands FILE --run`` with the executive layer on flies the file to its end on each autopilot (the
  model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``): every command FINISHED, none CANCELLED, the
  vehicle seen at the far waypoint by an independent pymavlink ground station;
* during an operator's joystick break-in a mission GO_TO_POINT is refused (409 with the reason) and the
  vehicle, sampled for seconds, does not move toward it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from companion.builder import Companion, CompanionConfig, build_companion
from companion.flight import EventKind, command_from_dict, load_commands
from companion.main import add_companion_arguments, config_from_args
from companion.tst.executor import ExecContext
from companion.tst.leaves.fly_to import FlyToExecutor
from companion.tst.plan import NodePlan
from companion.tst.tree import TstNode
from groundstation.auth import Tokens
from harness.autopilot import AUTOPILOTS, start_autopilot
from harness.behaviors import World
from harness.fake_autopilot import unanswered_url
from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for
from mission_specs import bundled
from taskflight_common.yamlio import ConfigError

OPERATOR, MISSION, OBSERVER = "op-token-1", "mission-token-1", "observer-token-1"
TOKENS = {"operator": [OPERATOR], "mission": [MISSION], "observer": [OBSERVER]}
TAKE_OFF = {"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}}
WAIT_1 = {"end": {"e_wait": 1.0}}


# --- credentials ------------------------------------------------------------------------------------------
@contextmanager
def surface(**kw: Any) -> Iterator[tuple[Companion, Any]]:
    """A companion with its executive layer whose autopilot never answers (never started), its control
    surface served; yields it and a client factory ``client(token)``."""
    companion = build_companion(CompanionConfig(unanswered_url(), control_port=0, missions=False, **kw))
    server = companion.control_server().start()
    clients: list[httpx.Client] = []

    def client(token: str | None) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        c = httpx.Client(base_url=server.url, timeout=10.0, headers=headers)
        clients.append(c)
        return c
    try:
        yield companion, client
    finally:
        for c in clients:
            c.close()
        server.close()
        companion.node.close()


def test_requesters_come_from_token_roles() -> None:
    with surface(control_tokens=TOKENS) as (companion, client):
        op, mission, observer = client(OPERATOR), client(MISSION), client(OBSERVER)
        coordinator = companion.layer.coordinator if companion.layer else None
        assert coordinator is not None
        for asked in ("operator", "emergency"):
            r = mission.post("/behaviors/activate", json={"text": "WAIT duration: 1", "requester": asked})
            assert r.status_code == 403 and f"not as {asked}" in r.json()["error"], r.text
            r = mission.post("/behaviors/inhibit", json={"behavior": "WAIT", "requester": asked})
            assert r.status_code == 403, r.text
        r = op.post("/behaviors/activate", json={"text": "WAIT duration: 1", "requester": "emergency"})
        assert r.status_code == 403 and "not as emergency" in r.json()["error"], r.text
        assert not [q for q in coordinator.requests if q["behavior"] == "WAIT"]  # none reached it
        # an observer reads, never writes
        assert observer.get("/status").status_code == 200
        assert observer.get("/behaviors").status_code == 200
        for path, body in (("/commands", TAKE_OFF), ("/behaviors/activate", {"text": "LAND"}), ("/run", None),
                           ("/stop", None), ("/beliefs", {"add": ["object(5, place)"]})):
            r = observer.post(path, json=body)
            assert r.status_code == 403 and "observer" in r.json()["error"], (path, r.text)
        assert observer.post("/behaviors/check", json={"text": "WAIT duration: 1"}).status_code == 200
        assert mission.post("/mission/pause").status_code == 403  # the break-in is the operator's
        assert client(None).get("/status").status_code == 401
        assert client("wrong").post("/commands", json=TAKE_OFF).status_code == 401
        # the flight-command path: FLY_COMMANDS of the caller's requester
        r = mission.post("/commands", json={"commands": [TAKE_OFF, WAIT_1]})
        assert r.status_code == 200, r.text
        act = coordinator.activation("FLY_COMMANDS")
        assert act is not None and act.requester == "mission"
        assert r.json()["activation_id"] == act.activation_id
        r = mission.post("/commands", json=WAIT_1)  # the same requester: appended to its activation
        assert r.status_code == 200 and r.json()["activation_id"] == act.activation_id, r.text
        assert len(act.controller.status()["command_ids"]) == 3
        r = op.post("/commands", json=TAKE_OFF)  # the operator takes over: a new activation
        assert r.status_code == 200, r.text
        held = coordinator.activation("FLY_COMMANDS")
        assert held is not None and held.requester == "operator" and held.activation_id != act.activation_id
        assert next(e for e in coordinator.ended if e.activation_id == act.activation_id).cause.value \
            == "interrupted"
        before = [e.id for e in companion.node.queue.entries]
        for path, body in (("/commands", WAIT_1), ("/stop", None), ("/reset", None), ("/run", None),
                           ("/pause_direct", None), ("/user_confirm", None)):
            r = mission.post(path, json=body)
            assert r.status_code == 409 and "operator" in r.json()["error"], (path, r.text)
        r = mission.post("/behaviors/inhibit", json={"behavior": "FLY_COMMANDS"})
        assert r.status_code == 409 and "priority over mission" in r.json()["reason"], r.text
        r = mission.post("/behaviors/activate", json={"text": "FLY_COMMANDS commands: \"[]\""})
        assert r.status_code == 409, r.text
        assert [e.id for e in companion.node.queue.entries] == before
        assert coordinator.activation("FLY_COMMANDS") is held
        assert op.post("/stop").status_code == 200
        r = op.post("/behaviors/inhibit", json={"behavior": "FLY_COMMANDS"})
        assert r.status_code == 200 and r.json()["accepted"], r.text


def test_open_surface_is_the_operator_on_loopback_only() -> None:
    with surface() as (companion, client):
        http = client(None)
        r = http.post("/behaviors/activate", json={"text": "WAIT duration: 1", "requester": "emergency"})
        assert r.status_code == 403, r.text
        r = http.post("/commands", json=TAKE_OFF)
        assert r.status_code == 200, r.text
        act = companion.layer.coordinator.activation("FLY_COMMANDS") if companion.layer else None
        assert act is not None and act.requester == "operator"
    with pytest.raises(ValueError, match="without tokens"):
        CompanionConfig(unanswered_url(), control_host="0.0.0.0")
    CompanionConfig(unanswered_url(), control_host="0.0.0.0", control_tokens=TOKENS)  # with tokens: fine


def test_tokens_file_roles(tmp_path: Path) -> None:
    path = tmp_path / "tokens.yaml"
    path.write_text(yaml.safe_dump(TOKENS))
    parser = __import__("argparse").ArgumentParser()
    add_companion_arguments(parser)
    args = parser.parse_args(["--autopilot", unanswered_url(), "--tokens", str(path), "--control-host",
                              "0.0.0.0", "--no-behaviors"])
    assert config_from_args(args).control_tokens == TOKENS
    with pytest.raises(ConfigError, match=r"mission: unknown role: the ground service takes operator, obs"):
        Tokens.load(path)  # the ground service's own file has no mission role: refused, naming it
    path.write_text("operator: [a]\nemergency: [b]\n")
    with pytest.raises(ConfigError, match=r"tokens\.yaml:2: emergency: unknown role"):
        config_from_args(args)


# --- the coordinator: the operator's assistance pause suspends, and outranks the mission ------------------
def test_operator_break_in_suspends_the_mission_behavior_and_keeps_the_mission_out() -> None:
    w = World()
    w.take_off()
    go = w.activate("GO_TO_POINT coordinate: (10, 0, 5)")
    assert go.accepted, go.reason
    w.run(1.0)
    pause = w.activate("REQUEST_OPERATOR_ASSISTANCE control: hover", "operator")
    assert pause.accepted and pause.stopped == (), pause  # suspended, not stopped
    act = w.coordinator.activation("GO_TO_POINT")
    assert act is not None and act.activation_id == go.activation_id
    w.run(4.0)  # the hover routine brakes (jerk-limited), then holds
    assert act.controller.paused
    here = w.pos_neu
    for text in ("GO_TO_POINT coordinate: (-10, 0, 5)", "LAND", "KEEP_MOVING velocity: (1, 0, 0)",
                 "FOLLOW_EXTERNAL_VELOCITY"):
        r = w.activate(text, "mission")
        assert not r.accepted and "REQUEST_OPERATOR_ASSISTANCE" in r.reason and "operator" in r.reason, r
    assert not w.coordinator.inhibit(pause.activation_id or "", "mission").accepted
    assert w.coordinator.authority("mission", "run") is not None
    assert w.coordinator.authority("operator", "run") is None
    w.run(3.0)
    assert math.dist(w.pos_neu, here) < 0.5 and "KEEP_HOVERING" not in w.active()
    w.queue.user_confirm()  # the operator confirms: the mission's GO_TO_POINT goes on and gets there
    assert w.wait_ended("REQUEST_OPERATOR_ASSISTANCE", 2).cause.value == "goal_achieved"
    assert w.wait_ended("GO_TO_POINT", 30).cause.value == "goal_achieved"
    assert math.dist(w.pos_neu, (10, 0, 5)) < 0.5


def test_a_mission_node_refused_during_a_break_in_fails_with_the_reason() -> None:
    w = World()
    w.take_off()
    assert w.activate("REQUEST_OPERATOR_ASSISTANCE control: joystick", "operator").accepted
    marks: list[tuple[str, dict[str, Any]]] = []
    node = TstNode("fly-to", {"position": [57.0, 15.0, 5.0]}, id="goto")
    ex = FlyToExecutor(node, NodePlan("goto", "fly-to", position_neu=(10.0, 0.0, 5.0)),
                       ExecContext(w.layer, mark=lambda event, **f: marks.append((event, f))))
    ex.start()
    assert ex.status.state == "failed", ex.status
    reason = next(f["reason"] for e, f in marks if e == "node_finished")
    assert "GO_TO_POINT" in reason and "REQUEST_OPERATOR_ASSISTANCE" in reason and "operator" in reason
    assert not w.coordinator.is_active("GO_TO_POINT")


def test_fly_commands_held_until_run_and_never_cancelled_by_the_default() -> None:
    w = World()
    w.take_off()
    commands = [command_from_dict({"horizontal": {"mode": "POS", "north": 6.0, "east": 0.0},
                                   "vertical": {"mode": "POS", "altitude": 5.0}, "end": {"e_h": True}}),
                command_from_dict({"end": {"e_user": True}})]
    r = w.coordinator.fly_commands(commands, "operator", hold=True)  # --commands FILE without --run
    assert r.accepted, r.reason
    here = w.pos_neu
    w.run(3.0)
    assert math.dist(w.pos_neu, here) < 0.3 and w.active().get("FLY_COMMANDS") == "operator"
    w.queue.run()
    w.run_until(lambda: w.queue.status().confirmation_required_status, 20, "waiting for the operator")
    assert w.active().get("FLY_COMMANDS") == "operator"  # the default does not take over an E_User wait
    more = w.coordinator.fly_commands([command_from_dict({"end": {"e_wait": 1.0}})], "operator")
    assert more.accepted and more.activation_id == r.activation_id  # appended to the same activation
    w.queue.user_confirm()
    assert w.wait_ended("FLY_COMMANDS", 10).cause.value == "goal_achieved"
    ids = set(w.coordinator.controllers["FLY_COMMANDS"].status()["command_ids"])
    events = [e for e in w.queue.events.since(0) if e.command_id in ids]
    assert len(ids) == 3 and {e.command_id for e in events if e.kind is EventKind.FINISHED} == ids
    assert not [e for e in events if e.kind is EventKind.CANCELLED]
    assert math.dist(w.pos_neu, (6.0, 0.0, 5.0)) < 0.3
    w.run_until(lambda: "KEEP_HOVERING" in w.active(), 2, "the default once the commands are done")


# --- --commands FILE --run flies the file with the executive layer on ---------------------------------------
@pytest.mark.integration
@pytest.mark.parametrize("kind", AUTOPILOTS)
def test_commands_file_runs_to_its_end_with_the_executive_layer(kind: str, tmp_path: Path) -> None:
    speedup = 5.0
    commands = tuple(load_commands(bundled("flight_commands_demo.yaml")))
    ap = start_autopilot(kind, tmp_path, speedup)
    try:
        companion = build_companion(CompanionConfig(ap.companion_url, commands=commands, run=True,
                                                    control_port=None, behavior_log=tmp_path / "b.jsonl"))
        assert companion.layer is not None  # the default: the executive layer on
        companion.start()
        try:
            node, coordinator = companion.node, companion.layer.coordinator
            far: list[tuple[float, float, float]] = []

            def track() -> bool:
                m = ap.gcs.last.get("LOCAL_POSITION_NED")  # the independent observer's
                if m is not None and m.x > 15.0:
                    far.append((m.x, m.y, -m.z))
                ended = [x for x in coordinator.ended if x.behavior == "FLY_COMMANDS"]
                return bool(ended) and not ap.gcs.armed()
            wait_for(track, 200.0 / speedup + 60, f"{kind}: the file flown and landed "
                     f"(queue {node.queue.status().to_dict()}, active {coordinator.status()['active']})")
            ended = [x for x in coordinator.ended if x.behavior == "FLY_COMMANDS"]
            assert len(ended) == 1 and ended[0].cause.value == "goal_achieved" and ended[0].requester \
                == "operator", ended
            kinds: dict[int, list[EventKind]] = {}
            for ev in node.queue.events.since(0):
                if ev.command_id is not None:
                    kinds.setdefault(ev.command_id, []).append(ev.kind)
            assert len(kinds) == len(commands), kinds
            assert all(EventKind.FINISHED in k and EventKind.CANCELLED not in k
                       for k in kinds.values()), kinds
            assert not [x for x in coordinator.ended if x.behavior == "KEEP_HOVERING"]  # never took over
            assert far and max(p[0] for p in far) > 19.0, far[-3:]  # at the far waypoint (20, 0, 8)
            assert any(abs(p[2] - 8.0) < 1.0 for p in far), far[-3:]
            n, e, d = ap.gcs.ned()
            assert math.hypot(n, e) < 1.5 and -d < 0.5, (n, e, d)  # back home, landed
        finally:
            companion.close()
    finally:
        ap.close()


# --- a mission request during an operator's break-in -----------------------------------------------------
FLIGHT_SESSION = SessionSpec("chain", 5.0, autopilots=[AUTOPILOTS[0]], localized=True, behaviors=True)


def activate(f: FlightSession, text: str, requester: str | None = None) -> httpx.Response:
    return f.post("/behaviors/activate", {"text": text, **({"requester": requester} if requester else {})})


@pytest.mark.integration
def test_mission_cannot_take_the_vehicle_during_an_operator_break_in(flight_session: FlightSession) -> None:
    f = flight_session
    assert f.layer is not None
    coordinator = f.layer.coordinator
    r = activate(f, "TAKE_OFF altitude: 5")
    assert r.status_code == 200, r.text
    take_off = r.json()["activation_id"]
    wait_for(lambda: any(e.activation_id == take_off for e in coordinator.ended), f.wall(60),
             "take-off ended")
    wait_for(lambda: coordinator.is_active("KEEP_HOVERING"), f.wall(5), "hovering")
    r = activate(f, "REQUEST_OPERATOR_ASSISTANCE control: joystick")
    assert r.status_code == 200 and r.json()["accepted"], r.text
    break_in = r.json()["activation_id"]
    f.wait_still(10)
    here = f.pos()
    target = (20.0, 0.0, 5.0)
    r = activate(f, f"GO_TO_POINT coordinate: {target}", "mission")
    assert r.status_code == 409, r.text
    why = r.json()["reason"]
    assert "REQUEST_OPERATOR_ASSISTANCE" in why and "operator" in why and not r.json()["accepted"], why
    r = f.post("/behaviors/inhibit", {"behavior": "REQUEST_OPERATOR_ASSISTANCE", "requester": "mission"})
    assert r.status_code == 409, r.text
    t_end = f.sim_time() + 5.0
    worst = 0.0
    while f.sim_time() < t_end:  # the vehicle stays where the operator holds it
        worst = max(worst, math.dist(f.pos(), here))
        f.sim_wait(0.1)
    assert worst < 1.0, f"moved {worst:.2f} m during the break-in"
    act = coordinator.activation("REQUEST_OPERATOR_ASSISTANCE")
    assert act is not None and act.activation_id == break_in and act.requester == "operator"
    assert not coordinator.is_active("GO_TO_POINT")
    # the operator ends the break-in; the vehicle lands
    assert f.post("/user_confirm").status_code == 200
    wait_for(lambda: any(e.activation_id == break_in for e in coordinator.ended), f.wall(5), "break-in ended")
    r = activate(f, "LAND")
    assert r.status_code == 200, r.text
    wait_for(lambda: not f.armed(), f.wall(60), "landed")
