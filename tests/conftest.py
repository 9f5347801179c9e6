"""The suite's fixtures, each defined once, and the test process's garbage collector kept from pausing the
flights that run inside it.

Fixtures. The rigs are :mod:`harness`'s; a test module that needs a variant says so in a module-level
constant the fixture reads (``request.module``), so that one definition serves every module:

* ``team_rig`` (module): :class:`~harness.team.TeamRig`, 3 vehicles at the module's ``SPEEDUP``, the
  allocation policy ``TEAM_POLICY`` (default greedy), ``TEAM_LOSS`` of the team packets dropped;
* ``ground_rig`` (module): :class:`~harness.ground.GroundRig` (the ground service as a process, so it can
  be killed); ``up_rig`` (module): :class:`~harness.up.UpRig` (``taskflight up``), with the camera
  scenario ``UP_SCENARIO`` (YAML text) when the module gives one;
* ``flight_session`` (module): :class:`~harness.flight_session.FlightSession` as the module's
  ``FLIGHT_SESSION`` (a :class:`~harness.flight_session.SessionSpec`) says, one per autopilot it names
  (parametrised in :func:`pytest_generate_tests`);
* ``gcs`` (module): the model in its own process and a ground station that heard it
  (:func:`~harness.model.sitl_and_gcs`) with the module's ``GCS_OPTIONS``, after the pre-arm checks pass
  when ``GCS_WAIT_PREARM``; ``sitl_port`` (module): the model's process on a UDP port, started with
  ``SITL_EXTRA``; ``sitl``: the model in the test process (:func:`~harness.model.model_in_process`),
  taken off to ``SITL_TAKEOFF_M`` when the module gives it;
* ``seen`` (module): what the module's differential scenario ``OBSERVE`` saw on each autopilot
  (:func:`~harness.differential.observed`);
* ``mavproxy``: MAVProxy typed into and an observing ground station (system 254) on the model at
  ``SPEEDUP``; ``mavproxy_out`` (module): MAVProxy's output and the commanding ground station;
* ``safety_rig``, ``fence_rig``, ``mission_rig``: the model's safety, fence and mission modules on the
  kinematic stand-in (:mod:`harness.kinematic`).

The garbage collector.

The flight tests run a companion in the pytest process, its setpoint stream paced on a model sped up
five times: a pause of the whole process costs five times as much simulated time. A full collection
walks every tracked object; with the suite's modules imported (~130 000 objects) it took 250-330 ms
here (0.5-0.7 s with the other core busy), enough to hand a take-off over seconds late (a CI failure:
the vehicle 1.5 m below its take-off altitude when the take-off ended). So, as the product's processes
do (:func:`taskflight_common.runtime.freeze_startup_heap`):

* once every test module is imported, the objects alive then are frozen out of the collector's sight;
* after each test, FastAPI's callable-classification caches (bounded at 4096 entries, keyed by the
  endpoint functions) are emptied: each control server's endpoints are closures over its node, so
  the cache would otherwise keep up to a hundred finished flight sessions alive and make every full
  collection walk them;
* the longest collector pauses are printed at the end of the run (a flaky flight test's first suspect).
"""

from __future__ import annotations

import gc
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from autopilot_model.modules.mission import MissionRunner, MissionStore
from autopilot_model.modules.safety import Safety
from harness.autopilot import AUTOPILOTS
from harness.differential import Observation, observed
from harness.flight_session import FlightSession, SessionSpec
from harness.ground import GroundRig
from harness.kinematic import KinematicVehicle, ModeSwitch, Recorder
from harness.mavproxy import Lines, MavProxy, mavproxy_on_model
from harness.model import SitlProcess, model_in_process, sitl_and_gcs
from harness.observer import Gcs
from harness.team import TeamRig
from harness.timing import SPEEDUP, wall
from harness.ui import Shots
from harness.up import UpRig
from taskflight_common.ports import free_ports

_pauses: list[tuple[float, int, str]] = []  # (seconds, generation, test) of the pauses over PAUSE_KEPT_S
_started: list[float] = []
_current = [""]
PAUSE_KEPT_S = 0.02


def _on_gc(phase: str, info: dict[str, Any]) -> None:
    if phase == "start":
        _started[:] = [time.perf_counter()]
    elif _started:
        took = time.perf_counter() - _started[0]
        if took >= PAUSE_KEPT_S:
            _pauses.append((took, int(info.get("generation", -1)), _current[0]))


def pytest_collection_finish(session: pytest.Session) -> None:
    gc.collect()
    gc.freeze()
    gc.callbacks.append(_on_gc)


def _clear_fastapi_caches() -> None:
    try:
        from fastapi.dependencies import models
    except ImportError:
        return
    for name in dir(models):
        fn = getattr(models, name)
        if name.endswith("_cached") and hasattr(fn, "cache_clear"):
            fn.cache_clear()


@pytest.fixture(autouse=True)
def _collector_hygiene(request: pytest.FixtureRequest) -> Iterator[None]:
    _current[0] = request.node.nodeid
    yield
    _clear_fastapi_caches()


def _name(request: pytest.FixtureRequest) -> str:
    """The module's name without ``test_``: the prefix of its temporary folders."""
    return request.module.__name__.rsplit(".", 1)[-1].removeprefix("test_")


# --- teams and the ground service (processes; one set a module) ---------------------------------------------
@pytest.fixture(scope="module")
def team_rig(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[TeamRig]:
    m = request.module
    r = TeamRig(tmp_path_factory.mktemp(_name(request)), n=3, speedup=m.SPEEDUP,
                policy=getattr(m, "TEAM_POLICY", "greedy"), loss=getattr(m, "TEAM_LOSS", 0.0))
    try:
        yield r
    finally:
        r.close()


@pytest.fixture(scope="module")
def ground_rig(request: pytest.FixtureRequest,
               tmp_path_factory: pytest.TempPathFactory) -> Iterator[GroundRig]:
    r = GroundRig(tmp_path_factory.mktemp(_name(request)), n=3, speedup=3.0)
    yield r
    r.close()


@pytest.fixture(scope="module")
def shots(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Shots:
    """The browser tests' screenshots, a folder per module (and $TASKFLIGHT_ARTEFACTS/ui when set)."""
    return Shots(tmp_path_factory.mktemp(f"{_name(request)}_screenshots"))


@pytest.fixture(scope="module")
def page(request: pytest.FixtureRequest, up_rig: UpRig) -> Iterator[Any]:
    """An operator's page (headless Chromium) on the module's ``up_rig``, once its fleet list shows every
    vehicle; the URLs it requested go into the module's ``URLS`` list when it has one; at the end, not one
    of them went to another host than the service."""
    from harness.ground import OPERATOR
    from harness.ui import foreign, operator_page

    urls: list[str] = getattr(request.module, "URLS", [])
    with operator_page(up_rig.ground.url, OPERATOR, up_rig.n, urls) as d:
        yield d
    assert not foreign(urls, up_rig.ground.url), "the page asked another host"


@pytest.fixture(scope="module")
def up_rig(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[UpRig]:
    tmp = tmp_path_factory.mktemp(_name(request))
    scenario: Path | None = None
    text = getattr(request.module, "UP_SCENARIO", None)
    if text is not None:
        scenario = tmp / "scenario.yaml"
        scenario.write_text(text)
    extra = getattr(request.module, "up_extra_args", None)  # a module's own `taskflight up` options
    r = UpRig(tmp, n=3, speedup=3.0, scenario=scenario, extra=extra(tmp) if extra is not None else ())
    yield r
    r.close()


# --- one companion in this process flying either autopilot --------------------------------------------------
def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """``flight_session``: one module-scoped session per autopilot the module's ``FLIGHT_SESSION`` names."""
    if "flight_session" in metafunc.fixturenames:
        spec: SessionSpec = metafunc.module.FLIGHT_SESSION
        if spec.autopilots:
            metafunc.parametrize("flight_session", spec.autopilots, indirect=True, scope="module")


@pytest.fixture(scope="module")
def flight_session(request: pytest.FixtureRequest,
                   tmp_path_factory: pytest.TempPathFactory) -> Iterator[FlightSession]:
    spec: SessionSpec = request.module.FLIGHT_SESSION
    kind = getattr(request, "param", "model")
    with spec.open(kind, tmp_path_factory.mktemp(f"{spec.name}_{kind}")) as session:
        yield session


# --- the model: in its own process with a ground station, or in this process --------------------------------
@pytest.fixture(scope="module")
def gcs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Gcs]:
    m = request.module
    with sitl_and_gcs(tmp_path_factory.mktemp(f"sitl_{_name(request)}"), **getattr(m, "GCS_OPTIONS",
                                                                                   {})) as g:
        if getattr(m, "GCS_WAIT_PREARM", False):
            g.wait_prearm(wall(30))
        yield g


@pytest.fixture(scope="module")
def sitl_port(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    proc = SitlProcess([f"udpin:127.0.0.1:{port}"], tmp_path_factory.mktemp(f"sitl_{_name(request)}"),
                       speedup=SPEEDUP, extra=getattr(request.module, "SITL_EXTRA", ()))
    try:
        yield port
    finally:
        proc.stop()


@pytest.fixture
def sitl(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Any]:
    with model_in_process(tmp_path, getattr(request.module, "SITL_TAKEOFF_M", None)) as s:
        yield s


# --- the differential scenarios -----------------------------------------------------------------------------
@pytest.fixture(scope="module", params=AUTOPILOTS)
def seen(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Observation:
    m = request.module
    return observed(request.param, m.OBSERVE, tmp_path_factory.mktemp, m.SPEEDUP)


# --- MAVProxy on the model ----------------------------------------------------------------------------------
@pytest.fixture
def mavproxy(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[MavProxy, Gcs]]:
    speedup = request.module.SPEEDUP  # MAVProxy is the pilot's GCS (255); the ground station observes
    with mavproxy_on_model(tmp_path, speedup, speedup=speedup, sysid=254, background=True) as rig:
        yield rig


@pytest.fixture(scope="module")
def mavproxy_out(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Lines, Gcs]]:
    d = tmp_path_factory.mktemp("mavproxy")
    with mavproxy_on_model(d, 10.0, interactive=False, persist=True) as (mp, g):
        yield mp.out, g


# --- the model's modules on the kinematic stand-in ----------------------------------------------------------
@pytest.fixture
def safety_rig() -> tuple[KinematicVehicle, Recorder, ModeSwitch, MissionStore, Safety]:
    v = KinematicVehicle()
    ep, modes, store = Recorder(), ModeSwitch(), MissionStore()
    return v, ep, modes, store, Safety(v, ep, modes, store)  # type: ignore[arg-type]  # stand-ins


@pytest.fixture
def fence_rig(safety_rig: tuple[KinematicVehicle, Recorder, ModeSwitch, MissionStore, Safety]) -> tuple[Any,
                                                                                                        ...]:
    v, ep, modes, _, safety = safety_rig
    return v, ep, modes, safety, safety.fence


@pytest.fixture
def mission_rig() -> tuple[KinematicVehicle, MissionStore, Recorder, MissionRunner]:
    v, store, ep = KinematicVehicle(), MissionStore(), Recorder()
    return v, store, ep, MissionRunner(v, store, ep)  # type: ignore[arg-type]  # a stand-in vehicle


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if not _pauses:
        return
    worst = sorted(_pauses, reverse=True)[:3]
    text = "; ".join(f"{took * 1e3:.0f} ms (generation {gen}) in {test or 'collection'}"
                     for took, gen, test in worst)
    terminalreporter.write_line(f"longest garbage-collector pauses: {text}")
