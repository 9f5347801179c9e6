"""The operator's stick cannot leave the platform's envelope (seed 000 Sec. IV-C/IV-D on the model).

A companion built with its defaults (the executive and mission layers on, the bundled indoor platform: a
40 x 40 m fence around home, a 10 m ceiling, 2 m/s) flies the bundled autopilot model over loopback UDP.
The operator takes the vehicle (FOLLOW_EXTERNAL_VELOCITY, operator requester) and pushes the stick north
into the fence, then up through the ceiling; the position the autopilot reports is sampled over the whole
run and never leaves the envelope delegation checks missions against.
"""

from __future__ import annotations

import time
from typing import Any

import pytest

from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
FLIGHT_SESSION = SessionSpec("envelope", SPEEDUP, autopilots=(), localized=True, missions=True)
#: the indoor platform's fence and ceiling (mission_specs/platform_indoor.yaml)
FENCE_N, CEILING = 20.0, 10.0
#: how far the vehicle may trail its reference (the model's position loop)
TRACKING_M = 0.3


def activate(f: FlightSession, text: str, requester: str) -> dict[str, Any]:
    r = f.post("/behaviors/activate", {"text": text, "requester": requester})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["accepted"], body
    return body


def push_stick(f: FlightSession, values: list[float], sim_s: float,
               samples: list[tuple[float, ...]]) -> None:
    """Push ``values`` for ``sim_s`` of autopilot time, sampling the reported position at each push."""
    t_end = f.sim_time() + sim_s
    deadline = time.monotonic() + f.wall(sim_s) + 30
    while f.sim_time() < t_end and time.monotonic() < deadline:
        r = f.post("/behaviors/joystick", {"values": values, "validity_s": 1.0})
        assert r.status_code == 200, r.text
        samples.append(f.pos())
        time.sleep(0.02)


def test_the_stick_stops_at_the_fence_and_the_ceiling(flight_session: FlightSession) -> None:
    f = flight_session
    env = f.node.queue.envelope
    assert env.altitude_ceiling == CEILING and not env.contains_ne((FENCE_N + 0.5, 0.0))
    take_off = activate(f, "TAKE_OFF altitude: 3", "mission")
    wait_for(lambda: any(e["activation_id"] == take_off["activation_id"]
                         for e in f.http.get("/behaviors").json()["ended"]), f.wall(60), "take-off ended")
    activate(f, "FOLLOW_EXTERNAL_VELOCITY", "operator")
    samples: list[tuple[float, ...]] = []
    push_stick(f, [2.0, 0.0, 0.0, 0.0], 25.0, samples)  # 50 m of stick: far beyond the fence at 20 m
    north = max(p[0] for p in samples)
    assert FENCE_N - 2.0 < north <= FENCE_N + TRACKING_M, f"north {north:.2f} m, the fence at {FENCE_N} m"
    push_stick(f, [0.0, 0.0, -1.0, 0.0], 15.0, samples)  # 15 m up from 3 m: through the 10 m ceiling
    top = max(-p[2] for p in samples)
    assert CEILING - 1.5 < top <= CEILING + TRACKING_M, f"altitude {top:.2f} m, the ceiling {CEILING} m"
    assert all(p[0] <= FENCE_N + TRACKING_M and -p[2] <= CEILING + TRACKING_M for p in samples)
    # the streamed reference itself never left the envelope
    assert all(env.contains_ne(sp.p[:2]) and -sp.p[2] <= CEILING + TRACKING_M
               for sp in f.streamed)
    r = f.post("/behaviors/activate", {"text": "LAND", "requester": "operator"})
    assert r.status_code == 200
