"""The HTTP control surface (companion.http) without an autopilot: real HTTP over loopback.

The node is never started (no tick thread, no link): its queue answers the verbs, lists, events and
external data on its own, which is all the surface needs. Each test gets its own node and server.
"""

from __future__ import annotations

import argparse
import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx
import pytest

import companion.http.events as events_api
from companion.builder import Companion, CompanionConfig, build_companion
from companion.flight import Envelope, command_from_dict, command_to_dict
from companion.flight.external import DEFAULT_MAX_VALIDITY_S
from companion.http import ControlServer, create_app, is_loopback
from companion.main import add_companion_arguments, control_token
from companion.node import QuadNode
from harness.fake_autopilot import unanswered_url
from harness.timing import wait_for
from taskflight_common.tokens import TOKEN_ENV

TAKE_OFF = {"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}}
WAIT_1 = {"end": {"e_wait": 1}}
GOTO = {"horizontal": {"mode": "POS", "north": 10, "east": 5}, "vertical": {"mode": "POS", "altitude": 6},
        "end": {"e_h": True, "e_v": True}}
TOKEN = "s3cret-token"

#: (method, path, request keywords, status, text the error names)
REFUSALS: list[tuple[str, str, dict[str, Any], int, str]] = [
    ("POST", "/commands", {"content": b"{not json", "headers": {"content-type": "application/json"}}, 400,
     "malformed JSON"),
    ("POST", "/commands", {"content": b"{not json"}, 400, "malformed JSON"),
    ("POST", "/commands", {}, 400, "expected a JSON body"),
    ("POST", "/commands", {"json": {"horizontal": {"mode": "POS", "north": 1.0}, "end": {"e_h": True}}}, 400,
     "east"),
    ("POST", "/commands", {"json": {"vertical": {"mode": "DNU"}, "end": {"e_v": True}}}, 400, "e_v"),
    ("POST", "/commands", {"json": {"commands": [WAIT_1, {"end": {}}]}}, 400, "commands[1]"),
    ("POST", "/commands", {"json": {"commands": [WAIT_1, {"end": 5}]}}, 400, "commands[1].end"),
    ("POST", "/commands", {"json": {"commands": []}}, 400, "commands"),
    ("POST", "/commands", {"json": {**WAIT_1, "colour": "red"}}, 400, "colour"),
    ("POST", "/commands", {"json": [WAIT_1]}, 400, "body"),
    ("POST", "/external/ext_vel", {"json": {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": "x"}}, 400,
     "validity_s"),
    ("POST", "/external/ext_vel", {"json": {"values": [1.0, True, 0.0, 0.0]}}, 400, "values[1]"),
    ("POST", "/external/ext_vel", {"json": {"values": [1.0, 2.0], "validity_s": 0.5}}, 400, "4 values"),
    ("POST", "/external/ext_vel", {"json": {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": 99}}, 400,
     "exceeds the maximum"),
    ("POST", "/external/no_such", {"json": {"values": [1.0]}}, 400, "unknown stream"),
    ("POST", "/pause_direct", {"json": {"routine_id": "nope"}}, 400, "unknown routine"),
    ("POST", "/pause_direct", {"json": {"routine_id": 5}}, 400, "routine_id"),
    ("POST", "/pause_after_current", {"json": {"routine": "hover"}}, 400, "routine"),
    ("POST", "/commands/1/retarget", {"json": {"north": "far"}}, 400, "north"),
    ("POST", "/commands/x/retarget", {"json": {"north": 1.0}}, 400, "command_id"),
    ("GET", "/events", {"params": {"since": "x"}}, 400, "since"),
    ("GET", "/events/wait", {"params": {"command_id": 1, "kinds": "LANDED"}}, 400, "LANDED"),
    ("GET", "/events/wait", {"params": {"command_id": 1, "timeout_s": 61}}, 400, "timeout_s"),
    ("GET", "/events/wait", {}, 400, "command_id"),
    ("GET", "/no/such/path", {}, 404, "/no/such/path"),
    ("POST", "/commands/1", {"json": WAIT_1}, 404, "/commands/1"),
    ("GET", "/run", {}, 405, "GET"),
    ("DELETE", "/commands", {}, 405, "DELETE"),
    ("POST", "/status", {}, 405, "POST"),
    ("POST", "/user_confirm", {}, 409, "nothing is waiting"),
    ("POST", "/commands/1/retarget", {"json": {"north": 1.0}}, 409, "not executing"),
]


def assert_error(r: httpx.Response, code: int, text: str = "") -> str:
    """The single error shape: exactly ``{"error": "<message>"}``; returns the message."""
    assert r.status_code == code, (r.status_code, r.text)
    body = r.json()
    assert isinstance(body, dict) and set(body) == {"error"}, body
    assert isinstance(body["error"], str) and body["error"], body
    assert text in body["error"], body
    return body["error"]


#: the companions the tests built, by their node's id (a test serves its node with other hosts and tokens)
_built: dict[int, Companion] = {}


def new_node(**kw: Any) -> QuadNode:
    companion = build_companion(CompanionConfig(unanswered_url(), behaviors=False,
                                                control_port=0, **kw))  # nobody answers; never started
    _built[id(companion.node)] = companion
    return companion.node


def control_server(node: QuadNode, **kw: Any) -> ControlServer:
    """A control surface over ``node`` (not started), as the builder makes it."""
    return _built[id(node)].control_server(**kw)


@contextmanager
def serve(node: QuadNode, token: str | None = None, host: str = "127.0.0.1",
          auth: str | None = None) -> Iterator[tuple[ControlServer, httpx.Client]]:
    server = control_server(node, host=host, token=token).start()
    headers = {"Authorization": f"Bearer {auth}"} if auth is not None else {}
    try:
        with httpx.Client(base_url=server.url, timeout=10.0, headers=headers) as http:
            yield server, http
    finally:
        server.close()


@pytest.fixture
def node() -> Iterator[QuadNode]:
    n = new_node()
    try:
        yield n
    finally:
        n.close()


@pytest.fixture
def http(node: QuadNode) -> Iterator[httpx.Client]:
    with serve(node) as (_, client):
        yield client


def snapshot(node: QuadNode) -> tuple[Any, ...]:
    q = node.queue
    return (q.status(), q.entries, q.events.last_seq, q.routine_id, q.external_sample("ext_vel"))


# --- the error shape ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("method", "path", "kw", "code", "text"), REFUSALS,
                         ids=[f"{c}-{m}-{p}-{i}" for i, (m, p, _, c, _) in enumerate(REFUSALS)])
def test_every_refusal_answers_one_error_shape(http: httpx.Client, method: str, path: str, kw: dict[str, Any],
                                               code: int, text: str) -> None:
    assert_error(http.request(method, path, **kw), code, text)


def test_refused_requests_change_nothing(node: QuadNode, http: httpx.Client) -> None:
    r = http.post("/commands", json={"commands": [TAKE_OFF, GOTO]})
    assert r.status_code == 200, r.text
    before = snapshot(node)
    listed = http.get("/commands").json()
    for method, path, kw, code, text in REFUSALS:
        assert_error(http.request(method, path, **kw), code, text)
    assert snapshot(node) == before
    assert http.get("/commands").json() == listed


def test_batch_with_one_bad_command_adds_nothing(http: httpx.Client) -> None:
    first = http.post("/commands", json=TAKE_OFF).json()
    message = assert_error(http.post("/commands", json={"commands": [WAIT_1, GOTO, {"end": {}}]}), 400,
                           "commands[2]")
    assert "end" in message
    listed = http.get("/commands").json()
    assert [c["id"] for c in listed["commands"]] == first["ids"]
    added = [e for e in http.get("/events").json()["events"] if e["kind"] == "ADDED"]
    assert [e["command_id"] for e in added] == first["ids"]


def test_batch_refused_by_the_envelope_adds_nothing() -> None:
    """Valid commands, one of them outside the envelope: the queue's atomic add refuses all of them."""
    node = new_node(envelope=Envelope(altitude_ceiling=20.0))
    try:
        with serve(node) as (_, http):
            too_high = {"vertical": {"mode": "POS", "altitude": 50}, "end": {"e_v": True}}
            before = snapshot(node)
            assert_error(http.post("/commands", json={"commands": [GOTO, too_high]}), 400, "commands[1]")
            assert snapshot(node) == before
            assert http.get("/commands").json()["commands"] == []
    finally:
        node.close()


# --- OpenAPI -------------------------------------------------------------------------------------------
def test_openapi_documents_request_and_response_schemas(http: httpx.Client) -> None:
    doc = http.get("/openapi.json").json()
    schemas = doc["components"]["schemas"]

    def refs(schema: dict[str, Any]) -> set[str]:
        found = {schema["$ref"].rsplit("/", 1)[1]} if "$ref" in schema else set()
        for key in ("oneOf", "anyOf"):
            for sub in schema.get(key, []):
                found |= refs(sub)
        return found

    def body(path: str) -> set[str]:
        names = refs(doc["paths"][path]["post"]["requestBody"]["content"]["application/json"]["schema"])
        assert names and names <= set(schemas), (path, names)
        return names

    assert body("/commands") == {"FlightCommandModel", "CommandBatch"}
    assert body("/external/{stream}") == {"ExternalSample"}
    assert body("/pause_direct") == {"PauseRequest"}
    assert body("/pause_after_current") == {"PauseRequest"}
    assert body("/commands/{command_id}/retarget") == {"RetargetRequest"}
    assert set(schemas["RetargetRequest"]["properties"]) == {"north", "east", "altitude", "speed", "heading"}
    assert schemas["FlightCommandModel"]["required"] == ["end"]
    assert schemas["FlightCommandModel"].get("examples")
    assert set(schemas["ExternalSample"]["properties"]) == {"values", "validity_s", "age_ms", "seq", "sender"}
    expected = {("get", "/status"): "StatusResponse", ("get", "/commands"): "CommandListResponse",
                ("post", "/commands"): "AddedResponse", ("get", "/events"): "EventsResponse",
                ("get", "/events/wait"): "EventWaitResponse",
                ("get", "/pause_routines"): "PauseRoutinesResponse",
                ("post", "/external/{stream}"): "AcceptedResponse", ("post", "/run"): "VerbResponse",
                ("post", "/commands/{command_id}/retarget"): "FlightCommandModel",
                ("get", "/params/{name}"): "ParamAnswer", ("put", "/params/{name}"): "ParamAnswer",
                ("post", "/fence"): "FenceAnswer"}
    operations = 0
    for path, ops in doc["paths"].items():
        for method, op in ops.items():
            operations += 1
            answers = op["responses"]
            assert "422" not in answers, (method, path)
            assert refs(answers["4XX"]["content"]["application/json"]["schema"]) == {"ErrorResponse"}
            names = refs(answers["200"]["content"]["application/json"]["schema"])
            assert names and names <= set(schemas), (method, path, answers["200"])
            if (method, path) in expected:
                assert names == {expected[method, path]}, (method, path)
    assert operations == 17  # the QAPI's 14, the autopilot parameters (get, put) and its fence (post)
    assert set(schemas["AddedResponse"]["properties"]) == {"ids", "indices", "activation_id"}
    assert set(schemas["ErrorResponse"]["properties"]) == {"error"}


# --- commands, events ----------------------------------------------------------------------------------
def test_post_commands_answers_ids_and_indices_and_get_lists_them(node: QuadNode, http: httpx.Client) -> None:
    r = http.post("/commands", json=TAKE_OFF)
    assert r.status_code == 200, r.text
    one = r.json()
    assert set(one) == {"ids", "indices"} and one["indices"] == [0] and len(one["ids"]) == 1
    r = http.post("/commands", json={"commands": [GOTO, WAIT_1]})
    assert r.status_code == 200, r.text
    two = r.json()
    assert two["indices"] == [1, 2]
    ids = one["ids"] + two["ids"]
    assert len(set(ids)) == 3 and ids == sorted(ids)
    assert ids == [e.id for e in node.queue.entries]
    listed = http.get("/commands").json()
    assert listed["current_command_index"] == 0
    assert listed["current_command_id"] == ids[0]
    assert listed["generation"] == 0
    assert [(c["id"], c["index"]) for c in listed["commands"]] == list(zip(ids, range(3), strict=True))
    assert [c["command"] for c in listed["commands"]] == [
        command_to_dict(command_from_dict(c)) for c in (TAKE_OFF, GOTO, WAIT_1)]
    assert http.post("/reset").status_code == 200
    after = http.get("/commands").json()
    assert after["commands"] == [] and after["generation"] == 1 and after["current_command_id"] is None
    r = http.post("/commands", json=WAIT_1).json()
    assert r["indices"] == [0] and r["ids"][0] > ids[-1]  # ids are never reused


def test_events_list_added_commands(http: httpx.Client) -> None:
    empty = http.get("/events").json()
    assert empty == {"events": [], "last_seq": 0}
    ids = http.post("/commands", json={"commands": [TAKE_OFF, GOTO]}).json()["ids"]
    r = http.get("/events")
    assert r.status_code == 200
    events = r.json()
    assert [(e["kind"], e["command_id"], e["index"]) for e in events["events"]] == [
        ("ADDED", ids[0], 0), ("ADDED", ids[1], 1)]
    assert events["last_seq"] == events["events"][-1]["seq"]
    assert all(e["generation"] == 0 and e["t_s"] is None for e in events["events"])
    later = http.get("/events", params={"since": events["last_seq"]}).json()
    assert later == {"events": [], "last_seq": events["last_seq"]}
    third = http.post("/commands", json=WAIT_1).json()["ids"][0]
    later = http.get("/events", params={"since": events["last_seq"]}).json()
    assert [(e["kind"], e["command_id"]) for e in later["events"]] == [("ADDED", third)]
    assert later["last_seq"] == events["last_seq"] + 1


def test_events_wait(node: QuadNode, http: httpx.Client) -> None:
    cid = http.post("/commands", json=TAKE_OFF).json()["ids"][0]
    # the ADDED event has happened: answered at once (the server would wait 30 s, the client 10)
    r = http.get("/events/wait", params={"command_id": cid, "kinds": "ADDED", "timeout_s": 30})
    assert r.status_code == 200, r.text
    event = r.json()["event"]
    assert event["kind"] == "ADDED" and event["command_id"] == cid and event["index"] == 0
    # nothing ever finishes it (no ticks): null at the deadline
    r = http.get("/events/wait", params={"command_id": cid, "kinds": "FINISHED,FAILED", "timeout_s": 0.2})
    assert r.status_code == 200 and r.json() == {"event": None}
    # a waiter blocked on the default kinds (terminal) is woken by reset's CANCELLED
    answers: list[httpx.Response] = []

    def wait() -> None:
        with httpx.Client(base_url=str(http.base_url), timeout=30.0) as other:
            answers.append(other.get("/events/wait", params={"command_id": cid, "timeout_s": 20}))

    waiter = threading.Thread(target=wait)
    waiter.start()
    assert http.post("/reset").status_code == 200
    waiter.join(timeout=25.0)
    assert not waiter.is_alive() and len(answers) == 1
    assert answers[0].status_code == 200
    assert answers[0].json()["event"]["kind"] == "CANCELLED"
    assert answers[0].json()["event"]["command_id"] == cid


def test_events_wait_refused_when_too_many_wait(node: QuadNode, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(events_api, "MAX_WAITERS", 0)
    with serve(node) as (_, http):
        assert_error(http.get("/events/wait", params={"command_id": 1, "timeout_s": 0}), 429, "waiting")


def test_close_ends_a_pending_wait(node: QuadNode) -> None:
    answers: list[object] = []
    server = control_server(node).start()

    def wait() -> None:
        try:
            with httpx.Client(base_url=server.url, timeout=30.0) as client:
                answers.append(client.get("/events/wait", params={"command_id": 10**9, "timeout_s": 60}))
        except httpx.HTTPError as exc:  # the request may also meet a closed server
            answers.append(exc)

    waiter = threading.Thread(target=wait)
    waiter.start()
    wait_for(lambda: server.server.server_state.connections or not waiter.is_alive(), 10.0, "the request")
    server.close()
    waiter.join(timeout=20.0)
    assert not waiter.is_alive(), "a pending /events/wait kept running after close()"
    if isinstance(answers[0], httpx.Response):
        assert answers[0].json() == {"event": None}


def test_retarget(node: QuadNode, http: httpx.Client) -> None:
    cid = http.post("/commands", json=GOTO).json()["ids"][0]
    assert http.post("/run").status_code == 200  # no ticks: the command never starts executing
    before = snapshot(node)
    assert_error(http.post(f"/commands/{cid}/retarget", json={"north": 12.0}), 409, "not executing")
    assert_error(http.post(f"/commands/{cid + 1000}/retarget", json={"speed": 2.0}), 409, "not executing")
    assert_error(http.post(f"/commands/{cid}/retarget", json={"north": 1.0, "up": 2.0}), 400, "up")
    assert_error(http.post(f"/commands/{cid}/retarget", json={"speed": True}), 400, "speed")
    assert snapshot(node) == before


# --- verbs ----------------------------------------------------------------------------------------------
def test_verbs_and_lists(node: QuadNode, http: httpx.Client) -> None:
    status = http.get("/status")
    assert status.status_code == 200
    assert {"queue", "commands", "routine_id", "flight", "link", "vehicle", "node"} <= set(status.json())
    assert status.json()["queue"]["queue_status"] == "STOPPED"
    assert set(http.get("/pause_routines").json()["pause_routines"]) >= {"hover", "joystick"}
    r = http.post("/run")
    assert r.status_code == 200 and r.json()["ok"] is True
    assert r.json()["status"]["queue_status"] == "RUNNING"
    r = http.post("/pause_direct", json={"routine_id": "hover"})
    assert r.status_code == 200, r.text
    assert node.queue.routine_id == "hover"
    assert_error(http.post("/pause_direct"), 409, "already in pause routine")
    assert_error(http.post("/pause_after_current", json={}), 409, "already in pause routine")
    assert http.post("/stop").json()["status"]["queue_status"] == "STOPPED"
    assert node.queue.routine_id is None
    assert http.post("/pause_after_current").status_code == 200  # nothing executing: pauses at once
    assert node.queue.routine_id == "hover"
    assert http.post("/reset").json()["status"]["generation"] == 1
    r = http.post("/external/ext_vel", json={"values": [1, 0.0, 0.0, 0.0], "validity_s": 0.5})
    assert r.status_code == 200 and r.json() == {"accepted": True, "reason": None}
    sample = node.queue.external_sample("ext_vel")
    assert sample is not None and sample.values == (1.0, 0.0, 0.0, 0.0)


# --- authentication, host -----------------------------------------------------------------------------
def test_token_required_when_set(node: QuadNode) -> None:
    with serve(node, token=TOKEN) as (_, http):
        before = snapshot(node)
        for headers, text in [({}, "authentication required"),
                              ({"Authorization": "Bearer wrong"}, "invalid token"),
                              ({"Authorization": f"Basic {TOKEN}"}, "Bearer"),
                              ({"Authorization": f"Bearer {TOKEN}x"}, "invalid token")]:
            for method, path, kw in [("GET", "/status", {}), ("POST", "/commands", {"json": TAKE_OFF}),
                                     ("POST", "/commands", {"content": b"{not json"}),
                                     ("POST", "/run", {}), ("GET", "/no/such/path", {}), ("GET", "/run", {})]:
                r = http.request(method, path, headers=headers, **kw)
                assert_error(r, 401, text)
                assert r.headers["www-authenticate"].startswith("Bearer")
        assert snapshot(node) == before
        doc = http.get("/openapi.json")  # the description stays open
        assert doc.status_code == 200
        assert doc.json()["components"]["securitySchemes"]["bearer"] == {"type": "http", "scheme": "bearer"}
        assert http.get("/docs").status_code == 200
        good = {"Authorization": f"Bearer {TOKEN}"}
        assert http.get("/status", headers=good).status_code == 200
        r = http.post("/commands", json=TAKE_OFF, headers={"authorization": f"bearer {TOKEN}"})
        assert r.status_code == 200 and r.json()["indices"] == [0]
        assert_error(http.get("/no/such/path", headers=good), 404)
        assert_error(http.post("/user_confirm", headers=good), 409)


def test_control_host_any_address_answers_on_loopback(node: QuadNode) -> None:
    with serve(node, token=TOKEN, host="0.0.0.0", auth=TOKEN) as (server, _):
        assert server.url == f"http://127.0.0.1:{server.port}"
        loopback = f"http://127.0.0.1:{server.port}"
        with httpx.Client(timeout=10.0) as client:
            r = client.get(f"{loopback}/status", headers={"Authorization": f"Bearer {TOKEN}"})
            assert r.status_code == 200, r.text
            assert_error(client.get(f"{loopback}/status"), 401)


def test_without_tokens_loopback_only_and_says_so(node: QuadNode, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="companion.http.server"):
        control_server(node, host="0.0.0.0", token=TOKEN)
        assert not [r for r in caplog.records if r.name == "companion.http.server"]
        with pytest.raises(ValueError, match=r"0\.0\.0\.0 without tokens"):
            control_server(node, host="0.0.0.0")
        control_server(node, host="127.0.0.1")
    warnings = [r for r in caplog.records
                if r.name == "companion.http.server" and r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "without tokens" in warnings[0].getMessage()


def test_empty_token_refused(node: QuadNode) -> None:
    with pytest.raises(ValueError, match="token"):
        create_app(node, token="")


def test_loopback_detection() -> None:
    assert all(is_loopback(h) for h in ("127.0.0.1", "127.1.2.3", "::1", "[::1]", "localhost"))
    assert not any(is_loopback(h) for h in ("0.0.0.0", "::", "192.168.1.5", "example.org"))


# --- command line ----------------------------------------------------------------------------------------
def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_companion_arguments(parser)
    return parser.parse_args(["--autopilot", "udpout:127.0.0.1:14550", *argv])


def test_cli_control_options(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    args = parse([])
    assert args.control_host == "127.0.0.1" and control_token(args) is None
    assert args.max_validity is None  # run_companion: DEFAULT_MAX_VALIDITY_S
    args = parse(["--control-host", "0.0.0.0", "--control-token", "abc", "--max-validity", "2.5"])
    assert args.control_host == "0.0.0.0" and control_token(args) == "abc" and args.max_validity == 2.5
    monkeypatch.setenv(TOKEN_ENV, "from-env")
    assert control_token(parse([])) == "from-env"
    assert control_token(parse(["--control-token", "abc"])) == "abc"
    monkeypatch.setenv(TOKEN_ENV, "")
    assert control_token(parse([])) is None


def test_max_validity_reaches_the_queue() -> None:
    node = new_node(max_validity_s=1.0)
    try:
        assert node.queue.max_validity_s == 1.0 != DEFAULT_MAX_VALIDITY_S
        with serve(node) as (_, http):
            r = http.post("/external/ext_vel", json={"values": [0, 0, 0, 0], "validity_s": 2.0})
            assert_error(r, 400, "exceeds the maximum of 1 s")
    finally:
        node.close()
