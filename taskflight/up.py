"""``taskflight up``: a whole simulated fleet in one command (seed 003 Fig. 1).

    taskflight up --vehicles N [--speedup K] [--ground-port P] [--tokens FILE] [--team-loss F]
                  [--team URL] [--team-key FILE] [--first-sysid K] [--state-dir DIR] [--base-instance I]
                  [--no-ground] [--control-host HOST] [--autopilot model|arducopter]

starts, each as a child process in a process group of its own (:mod:`taskflight.children`):

* the fleet: N bundled autopilot models in ONE process on one clock (:mod:`autopilot_model.fleet`).
  Vehicle i (from 0) is instance I+i: MAVLink system id K+i (``--first-sysid K``, default 1: several
  hosts starting vehicles for one team give each its own block of ids), ArduPilot SITL's TCP port
  5760+10(I+i) for
  any ground station (MAVProxy, QGroundControl: the lowest tier of seed 003 Fig. 1) and UDP 14550+10(I+i)
  for its companion. The default I = 0 gives the ports users expect (5760, 5770, ...); tests pick a free
  block with ``--base-instance``;
  With ``--autopilot arducopter``: one ArduPilot copter SITL per vehicle instead, on the same ports
  (:mod:`taskflight.arducopter_fleet`), and READY waits until every vehicle's EKF uses GPS;
* N companions, each on its vehicle's UDP port, K to a process (``--companions-per-process K``: each
  process a ``taskflight companion-host`` of K companions, :mod:`companion.host`; default: the vehicles
  spread over as many hosts as the machine has cores; K = 1: one ``taskflight companion`` process each, as
  on a real vehicle), all joined to one team link
  (a free multicast port of 239.255.70.1 unless ``--team``; ``--team-loss F`` appends ``?loss=F`` to the
  members' URL: that fraction of team packets is dropped at each member), each serving its control surface
  on a free port of loopback (``--control-host HOST`` for a ground service on another host) with the
  control token ``$TASKFLIGHT_CONTROL_TOKEN`` or a generated one (given in the environment, not the
  command line);
  every team-link packet is signed with the team key (``--team-key FILE``, else ``$TASKFLIGHT_TEAM_KEY``,
  else one generated for the fleet in ``<state-dir>/team.key``, mode 0600), passed to the companions and
  the ground service as ``TASKFLIGHT_TEAM_KEY=<path>`` in their environment (never on a command line);
* the ground service (``taskflight ground``, the team-control station and the operator's REST API),
  given every companion's URL and the control token; bearer tokens from ``--tokens FILE`` (YAML
  ``{operator: [..], observer: [..]}``) or generated (one each) and written to
  ``<state-dir>/tokens.yaml`` with mode 0600.

It waits until every vehicle is heard (each companion's ``GET /status`` says its MAVLink link is
connected and its ``GET /team`` hears every vehicle's row on the team link; the ground service answers
with every vehicle), then prints ``READY`` and a summary (URL, tokens, each vehicle's MAVLink ports).
A child that dies during start-up is reported with the tail of its log and everything is stopped (exit 1);
ports already taken are reported before anything starts (exit 2). Ctrl-C / SIGTERM stops everything:
the ground service, then the companions, then the models (SIGTERM with a deadline, then SIGKILL of each
child's process group). Logs: ``<state-dir>/logs/``; model parameters: ``<state-dir>/models/``; the
ground service's database: ``<state-dir>/ground.db``.
"""

from __future__ import annotations

import argparse
import logging
import os
import random
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from taskflight import arducopter_fleet as acf
from taskflight import hostproc
from taskflight.children import Child, first_dead, stop_all
from taskflight.up_args import AUTOPILOTS, DEFAULT_GROUND_PORT, PLATFORM, TEAM_GROUP
from taskflight.up_args import add_up_arguments as add_up_arguments  # its options, re-exported
from taskflight.up_ground import demo_tiles, ground_arguments, ground_available, write_fence, write_tokens
from taskflight_common.ports import free_ports, model_ports, port_free
from taskflight_common.tokens import TOKEN_ENV, load_tokens, new_token, role_tokens
from taskflight_common.yamlio import ConfigError

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[1]


def default_per_process(vehicles: int) -> int:
    """The default K: the companions spread over as many host processes as the machine has cores (one
    interpreter runs on one core at a time), e.g. 50 vehicles on 2 cores: 2 hosts of 25."""
    hosts = max(1, min(vehicles, os.cpu_count() or 1))
    return -(-vehicles // hosts)


class UpError(RuntimeError):
    """``taskflight up`` could not start; the message says why (and what a dead child printed)."""

    def __init__(self, message: str, status: int = 1) -> None:
        super().__init__(message)
        self.status = status


def free_team_url() -> str:
    """A multicast team URL on a free UDP port."""
    rng = random.Random()
    for _ in range(50):
        port = rng.randrange(20000, 60000)
        if port_free(socket.SOCK_DGRAM, port, ""):
            return f"udp://{TEAM_GROUP}:{port}"
    raise UpError("no free UDP port for the team link")


# --- tokens ------------------------------------------------------------------------------------------
def read_tokens(path: Path) -> dict[str, list[str]]:
    """The tokens file (:func:`taskflight_common.tokens.load_tokens`); UpError status 2 if it is wrong."""
    try:
        return load_tokens(path)
    except ConfigError as exc:
        raise UpError(str(exc), 2) from None


# --- options -----------------------------------------------------------------------------------------
@dataclass
class UpOptions:
    """What ``taskflight up`` starts (see the module docstring)."""

    vehicles: int
    state_dir: Path
    autopilot: str = "model"
    """``model``: the bundled models in one process; ``arducopter``: an ArduCopter SITL each
    (:mod:`taskflight.arducopter_fleet`)"""
    speedup: float = 1.0
    base_instance: int = 0
    ground: bool = True
    ground_port: int = DEFAULT_GROUND_PORT
    host: str = "127.0.0.1"
    mavlink_host: str = "127.0.0.1"
    control_host: str = "127.0.0.1"
    tokens_file: Path | None = None
    team: str | None = None
    team_loss: float = 0.0
    team_key: Path | None = None
    first_sysid: int = 1
    platform: Path = PLATFORM
    ready_timeout_s: float | None = None
    persist: bool = True
    companion_nice: int = 0
    resume_tasks: bool = False
    scenario: Path | None = None
    tiles: str | None = None
    """the ground's map tiles (``taskflight ground --tiles``); None: the demo's own, drawn at the first run"""

    #: companions per process (1: a ``taskflight companion`` each; None: :func:`default_per_process`)
    companions_per_process: int | None = None

    @property
    def per_process(self) -> int:
        """K, the companions per process (given, else :func:`default_per_process`)."""
        k = self.companions_per_process
        return k if k is not None else default_per_process(self.vehicles)

    def check(self) -> None:
        if not 1 <= self.vehicles <= 200:
            raise UpError(f"--vehicles must be within 1..200, got {self.vehicles}", 2)
        if not self.speedup >= 0:
            raise UpError(f"--speedup must be >= 0 (0: as fast as possible), got {self.speedup}", 2)
        if self.autopilot not in AUTOPILOTS:
            raise UpError(f"--autopilot must be one of {', '.join(AUTOPILOTS)}, got {self.autopilot!r}", 2)
        if self.autopilot == "arducopter" and not self.speedup > 0:
            raise UpError("--speedup 0 (as fast as possible) is the model's: ArduCopter SITL needs a "
                          "rate > 0", 2)
        if self.autopilot == "arducopter" and self.mavlink_host not in ("127.0.0.1", "0.0.0.0"):
            raise UpError(f"--mavlink-host {self.mavlink_host}: ArduCopter SITL serves its TCP ports on "
                          "every interface (0.0.0.0), it cannot be narrowed to one address", 2)
        if not 0 <= self.base_instance <= 255 - self.vehicles:
            raise UpError(f"instances {self.base_instance}..{self.base_instance + self.vehicles - 1} are "
                          "not all within 0..254", 2)
        if not 1 <= self.first_sysid <= 256 - self.vehicles:
            raise UpError(f"system ids {self.first_sysid}..{self.first_sysid + self.vehicles - 1} "
                          "(--first-sysid) are not all within 1..255", 2)
        if not 0.0 <= self.team_loss < 1.0:
            raise UpError(f"--team-loss must be within 0..1, got {self.team_loss}", 2)
        if self.team is not None and "loss=" in self.team and self.team_loss:
            raise UpError("give the loss either in --team or with --team-loss, not both", 2)
        if not 0 <= self.companion_nice <= 19:
            raise UpError(f"--companion-nice must be within 0..19, got {self.companion_nice}", 2)
        if not self.platform.is_file():
            raise UpError(f"--platform: no such file: {self.platform}", 2)
        if self.scenario is not None and not self.scenario.is_file():
            raise UpError(f"--scenario: no such file: {self.scenario}", 2)
        if self.companions_per_process is not None and not 1 <= self.companions_per_process <= 200:
            raise UpError("--companions-per-process must be within 1..200, got "
                          f"{self.companions_per_process}", 2)
        if not 1 <= self.ground_port <= 65535:
            raise UpError(f"--ground-port must be within 1..65535, got {self.ground_port}", 2)

    def ports_taken(self) -> list[str]:
        """Every MAVLink port (and the ground port) that is not free, described."""
        out = []
        for i in range(self.vehicles):
            tcp, udp = model_ports(self.base_instance + i)
            if not port_free(socket.SOCK_STREAM, tcp, self.mavlink_host):
                out.append(f"TCP {tcp} (vehicle {i}, sysid {self.first_sysid + i})")
            if not port_free(socket.SOCK_DGRAM, udp, self.mavlink_host):
                out.append(f"UDP {udp} (vehicle {i}, sysid {self.first_sysid + i})")
        if self.autopilot == "arducopter":
            out += acf.ports_taken(self.base_instance, self.vehicles, self.first_sysid, self.mavlink_host)
        if self.ground and not port_free(socket.SOCK_STREAM, self.ground_port, self.host):
            out.append(f"TCP {self.ground_port} (the ground service)")
        return out


@dataclass(frozen=True)
class VehicleInfo:
    index: int
    sysid: int
    instance: int
    tcp: int
    udp: int
    control_url: str


# --- the fleet ---------------------------------------------------------------------------------------
@dataclass
class Up:
    """The running fleet: :meth:`start` (returns once every vehicle is ready), :meth:`stop`."""

    opts: UpOptions
    children: list[Child] = field(default_factory=list)
    vehicles: list[VehicleInfo] = field(default_factory=list)
    tokens: dict[str, list[str]] = field(default_factory=dict)
    control_token: str = ""
    team_url: str = ""
    member_url: str = ""
    tokens_path: Path | None = None
    team_key_path: Path | None = None
    startup_s: float = float("nan")
    #: the system ids each companion process runs, by its name
    _hosted: dict[str, tuple[int, ...]] = field(default_factory=dict)
    _stopped: threading.Event = field(default_factory=threading.Event)
    #: ArduCopter SITL's binary and defaults file (``--autopilot arducopter``)
    _arducopter: tuple[str, Path] | None = None

    @property
    def ground_url(self) -> str | None:
        if not self.opts.ground:
            return None
        host = "127.0.0.1" if self.opts.host in ("0.0.0.0", "") else self.opts.host
        return f"http://{host}:{self.opts.ground_port}"

    @property
    def fleet(self) -> Child:
        """The models' process (the first ArduCopter SITL with ``--autopilot arducopter``)."""
        return self.children[0]

    def autopilots(self) -> list[Child]:
        """The autopilots' processes: the models' one, or an ArduCopter SITL per vehicle."""
        return [c for c in self.children if c.name == "fleet" or c.name.startswith("arducopter")]

    def companions(self) -> list[Child]:
        """The companions' processes (``companion<sysid>`` each, or ``companions<first>-<last>`` hosts)."""
        return [c for c in self.children if c.name.startswith("companion")]

    def companion_of(self, sysid: int) -> Child | None:
        """The process that runs vehicle ``sysid``'s companion."""
        return next((c for c in self.companions() if sysid in self._hosted.get(c.name, ())), None)

    def ground(self) -> Child | None:
        return next((c for c in self.children if c.name == "ground"), None)

    # --- start -------------------------------------------------------------------------------------
    def start(self, stop: threading.Event | None = None) -> Up:
        """Start everything and wait until ready (UpError, everything stopped, if it cannot)."""
        o = self.opts
        o.check()
        if o.autopilot == "arducopter":
            try:
                self._arducopter = (acf.binary(), acf.defaults_file(ROOT))
            except acf.ArduCopterError as exc:
                raise UpError(str(exc), 2) from None
        if o.ground and not ground_available():
            raise UpError("the ground service (taskflight ground) is not installed here; --no-ground starts "
                          "everything else", 2)
        taken = o.ports_taken()
        if taken:
            raise UpError("port(s) already in use: " + ", ".join(taken) + "; is another fleet running? "
                          "(--base-instance I moves the MAVLink ports to 5760+10I, --ground-port P)", 2)
        if o.team is not None:
            from companion.team.transport import open_transport

            try:  # a bad URL fails here, before anything starts
                open_transport(o.team, member=0, position_of=lambda m: None).close()
            except (ValueError, OSError) as exc:
                raise UpError(f"--team: {exc}", 2) from None
        o.state_dir.mkdir(parents=True, exist_ok=True)
        if o.tokens_file is not None:
            self.tokens = read_tokens(o.tokens_file)
            self.tokens_path = o.tokens_file
        else:
            self.tokens = role_tokens()
            self.tokens_path = o.state_dir / "tokens.yaml"
            if o.ground:
                write_tokens(self.tokens_path, self.tokens)
        self.team_key_path = self._team_key()
        # one token for every host of a team: the one in the environment when given (the ground service on
        # another host needs it to command these companions), else a new one
        self.control_token = os.environ.get(TOKEN_ENV) or new_token()
        self.team_url = o.team or free_team_url()
        self.member_url = self.team_url + (f"{'&' if '?' in self.team_url else '?'}loss={o.team_loss}"
                                           if o.team_loss else "")
        t0 = time.monotonic()
        try:
            self._start_fleet(stop)
            self._start_companions()
            if o.ground:
                self._start_ground()
            self._wait_ready(stop)
        except BaseException:
            self.stop()
            raise
        self.startup_s = time.monotonic() - t0
        return self

    def _team_key(self) -> Path:
        """The fleet's team key file: given, named by the environment, or generated in the state dir."""
        from companion.team.auth import generate_key_file, key_path, load_key

        given = key_path(str(self.opts.team_key) if self.opts.team_key else None)
        try:
            if given:
                load_key(given)
                return Path(given).resolve()
            return generate_key_file(self.opts.state_dir / "team.key").resolve()
        except (ValueError, OSError) as exc:
            raise UpError(f"--team-key: {exc}", 2) from None

    def _key_env(self) -> dict[str, str]:
        from companion.team.auth import ENV_KEY

        return {ENV_KEY: str(self.team_key_path)} if self.team_key_path is not None else {}

    def _exe(self) -> list[str]:
        return [sys.executable, "-m", "taskflight.cli"]

    def _deadline(self) -> float:
        t = self.opts.ready_timeout_s
        if t is None:  # ArduCopter is ready to arm at ~42 s of simulated time
            t = 60.0 + 3.0 * self.opts.vehicles + (90.0 / self.opts.speedup if self._arducopter else 0.0)
        return time.monotonic() + t

    def _check_alive(self) -> None:
        dead = first_dead(self.children)
        if dead is not None:
            tail = dead.tail()
            raise UpError(f"{dead.name} (pid {dead.pid}) exited with status {dead.returncode} during "
                          f"start-up; the end of {dead.log_path}:\n{tail}")

    def _vehicle_infos(self) -> None:
        o = self.opts
        ctl = free_ports(o.vehicles)
        for i in range(o.vehicles):
            tcp, udp = model_ports(o.base_instance + i)
            self.vehicles.append(VehicleInfo(i, o.first_sysid + i, o.base_instance + i, tcp, udp,
                                             f"http://127.0.0.1:{ctl[i]}"))

    def _start_fleet(self, stop: threading.Event | None) -> None:
        o = self.opts
        logs = o.state_dir / "logs"
        if self._arducopter is not None:
            self._vehicle_infos()
            self.children += acf.start_sitls(*self._arducopter, o.state_dir, self.vehicles, o.speedup)
            return
        argv = [sys.executable, "-m", "autopilot_model.fleet", "--vehicles", str(o.vehicles),
                "--base-instance", str(o.base_instance), "--first-sysid", str(o.first_sysid),
                "--speedup", f"{o.speedup:g}",
                "--state-dir", str(o.state_dir / "models"),
                "--mavlink-template", f"tcpin:{o.mavlink_host}:{{tcp}}",
                "--mavlink-template", f"udpin:{o.mavlink_host}:{{udp}}"]
        if not o.persist:
            argv.append("--no-persist")
        fleet_log = logs / "fleet.log"
        fleet_log.parent.mkdir(parents=True, exist_ok=True)
        fleet_log.write_bytes(b"")  # READY is looked for in this run's output only
        self.children.append(Child("fleet", argv, fleet_log, env=self._pythonpath(), cwd=ROOT).start())
        end = self._deadline()
        while "\nREADY" not in "\n" + self.fleet.tail(50):
            self._check_alive()
            if time.monotonic() > end:
                raise UpError(f"the fleet printed no READY line in time; the end of {fleet_log}:\n"
                              f"{self.fleet.tail()}")
            sleep_or_stop(stop, 0.05)
        self._vehicle_infos()

    def _pythonpath(self) -> dict[str, str]:
        pp = os.environ.get("PYTHONPATH", "")
        return {"PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), pp) if p)}

    def _companion_args(self, v: VehicleInfo) -> tuple[list[str], list[str]]:
        """Vehicle ``v``'s ``taskflight companion`` options: its own, and those every vehicle shares."""
        o = self.opts
        # the model listens on its UDP port; ArduCopter's SERIAL0 sends to the companion's
        endpoint = "udpin" if o.autopilot == "arducopter" else "udpout"
        own = ["--autopilot", f"{endpoint}:127.0.0.1:{v.udp}",
               "--control-port", v.control_url.rsplit(":", 1)[1],
               "--flight-log", str(o.state_dir / "logs" / f"flight{v.sysid}.jsonl")]
        common = ["--team", self.member_url, "--control-host", o.control_host, "--platform", str(o.platform),
                  *(["--scenario", str(o.scenario)] if o.scenario is not None else [])]
        return own, common

    def _start_companions(self) -> None:
        o = self.opts
        env = {**self._pythonpath(), **self._key_env(), TOKEN_ENV: self.control_token}
        nice = ["nice", "-n", str(o.companion_nice)] if o.companion_nice else []
        k = o.per_process
        for at in range(0, len(self.vehicles), k):
            group = self.vehicles[at:at + k]
            if k == 1:  # as on a real vehicle: one `taskflight companion` process
                own, common = self._companion_args(group[0])
                name, argv = f"companion{group[0].sysid}", [*self._exe(), "companion", *own, *common]
            else:
                name, argv = hostproc.host_command(self._exe(), group, self._companion_args)
            self._hosted[name] = tuple(v.sysid for v in group)
            self.children.append(Child(name, [*nice, *argv], o.state_dir / "logs" / f"{name}.log", env=env,
                                       cwd=ROOT).start())

    def _start_ground(self) -> None:
        o = self.opts
        assert self.tokens_path is not None
        argv = [*self._exe(), *ground_arguments(self.member_url, o.state_dir / "ground.db", o.host,
                                                o.ground_port, self.tokens_path, self.vehicles,
                                                o.resume_tasks)]
        fence = write_fence(o.platform, o.state_dir / "fence.yaml")
        if fence is not None:
            argv += ["--fence", str(fence)]
        argv += ["--tiles", o.tiles or str(demo_tiles(o.platform, o.state_dir / "tiles.mbtiles"))]
        self.children.append(Child("ground", argv, o.state_dir / "logs" / "ground.log",
                                   env={**self._pythonpath(), **self._key_env(),
                                        TOKEN_ENV: self.control_token},
                                   cwd=ROOT).start())

    def _wait_ready(self, stop: threading.Event | None) -> None:
        end = self._deadline()
        pending = {v.sysid for v in self.vehicles}
        want = set(pending)
        ground_ok = not self.opts.ground
        # ArduCopter: also ready to arm, its EKF using GPS (arducopter_fleet.ReadyWatch)
        watch = (acf.ReadyWatch({v.sysid: acf.watch_port(v.instance) for v in self.vehicles})
                 if self._arducopter is not None else None)
        unarmable = set(want) if watch is not None else set()
        note = time.monotonic() + 5.0
        try:
            while pending or unarmable or not ground_ok:
                self._check_alive()
                for v in [v for v in self.vehicles if v.sysid in pending]:
                    if self._vehicle_ready(v, want):
                        pending.discard(v.sysid)
                if watch is not None:
                    unarmable -= watch.poll()
                    if unarmable and time.monotonic() > note:
                        note += 5.0
                        log.info("waiting for ArduCopter: %d of %d vehicles ready to arm; %s",
                                 len(want) - len(unarmable), len(want), watch.progress(unarmable))
                if not pending and not ground_ok:
                    ground_ok = self._ground_ready()
                if time.monotonic() > end:
                    raise self._late(pending, unarmable, watch)
                sleep_or_stop(stop, 0.2)
        finally:
            if watch is not None:
                watch.close()

    def _late(self, pending: set[int], unarmable: set[int], watch: acf.ReadyWatch | None) -> UpError:
        what = (f"vehicle(s) {sorted(pending)} not heard" if pending
                else f"not ready to arm: {watch.progress(unarmable)}" if unarmable and watch
                else "the ground service did not answer with every vehicle")
        late = {c.name for s in pending if (c := self.companion_of(s)) is not None} | {
            f"arducopter{s}" for s in unarmable}  # by name: a Child (a mutable dataclass) is not hashable
        hint = "\n".join(f"--- {c.name}:\n{c.tail(5)}" for c in self.children
                         if c.name == "ground" or c.name in late)
        return UpError(f"not ready in time: {what}\n{hint}")

    def _get(self, url: str, token: str) -> Any:
        from taskflight.team_tasking import http_json

        return http_json("GET", url, token, timeout_s=5.0)

    def _vehicle_ready(self, v: VehicleInfo, want: set[int]) -> bool:
        """Its companion's MAVLink link is connected and it hears every vehicle on the team link."""
        try:
            status = self._get(v.control_url + "/status", self.control_token)
            team = self._get(v.control_url + "/team", self.control_token)
        except (OSError, ValueError, RuntimeError):
            return False
        return bool(status.get("link", {}).get("connected")) and want <= set(team.get("alive", []))

    def _ground_ready(self) -> bool:
        try:
            body = self._get(f"{self.ground_url}/api/vehicles", self.tokens["operator"][0])
        except (OSError, ValueError, RuntimeError):
            return False
        rows = body.get("vehicles", []) if isinstance(body, dict) else body if isinstance(body, list) else []
        heard = [r for r in rows if isinstance(r, dict) and r.get("team_state", "available") not in
                 ("unknown", "gone")]
        return len(heard) >= self.opts.vehicles

    # --- stop --------------------------------------------------------------------------------------
    def stop(self, timeout_s: float = 10.0) -> None:
        """The ground service, then the companions, then the autopilots; idempotent."""
        if self._stopped.is_set():
            return
        self._stopped.set()
        ground = [c for c in self.children if c.name == "ground"]
        stop_all(ground, timeout_s)
        stop_all(self.companions(), timeout_s)
        stop_all(self.autopilots(), timeout_s)

    # --- telling the user --------------------------------------------------------------------------
    def summary(self) -> str:
        o = self.opts
        lines = [f"READY {o.vehicles} vehicles, speedup {o.speedup:g}" + (" (lockstep)" if o.speedup == 0
                                                                          else "")
                 + (", ArduCopter SITL (every EKF using GPS)" if self._arducopter else "")
                 + f", started in {self.startup_s:.1f} s"]
        if o.ground:
            lines.append(f"ground service: {self.ground_url}  (API {self.ground_url}/api, "
                         f"docs {self.ground_url}/docs)")
            lines.append(f"operator token: {self.tokens['operator'][0]}")
            if self.tokens.get("observer"):
                lines.append(f"observer token: {self.tokens['observer'][0]}")
            lines.append(f"tokens file: {self.tokens_path}")
        lines.append(f"team link: {self.member_url}")
        if self.team_key_path is not None:
            lines.append(f"team key: {self.team_key_path}")
        pilots = (f"fleet {self.fleet.pid}" if self._arducopter is None  # one ArduCopter SITL per vehicle
                  else "arducopter " + " ".join(str(c.pid) for c in self.autopilots()))
        lines.append(f"pids: {pilots}; companions "  # each vehicle's companion process
                     + " ".join(str(c.pid) if (c := self.companion_of(v.sysid)) else "0"
                                for v in self.vehicles)
                     + (f"; ground {g.pid}" if (g := self.ground()) is not None else ""))
        mav_host = "0.0.0.0" if self._arducopter else o.mavlink_host  # SITL listens on every interface
        for v in self.vehicles:
            lines.append(f"vehicle {v.index}: sysid {v.sysid}  MAVLink tcp:{mav_host}:{v.tcp}  "
                         f"(mavproxy.py --master=tcp:127.0.0.1:{v.tcp})  companion {v.control_url}")
        if o.per_process > 1:
            lines.append(f"companion hosts: {len(self.companions())} processes of up to {o.per_process} "
                         "companions (taskflight companion-host)")
        lines.append(f"logs: {o.state_dir / 'logs'}; Ctrl-C stops everything")
        return "\n".join(lines)


def sleep_or_stop(stop: threading.Event | None, s: float) -> None:
    """Wait ``s`` seconds; KeyboardInterrupt if ``stop`` is set meanwhile (SIGINT/SIGTERM)."""
    if stop is None:
        time.sleep(s)
    elif stop.wait(s):
        raise KeyboardInterrupt


# --- command line ---------------------------------------------------------------------------------
def options_from_args(args: argparse.Namespace) -> UpOptions:
    state = Path(args.state_dir) if args.state_dir else Path(
        os.environ.get("TASKFLIGHT_STATE") or Path.home() / ".taskflight") / "up"
    return UpOptions(vehicles=args.vehicles, state_dir=state, speedup=args.speedup,
                     base_instance=args.base_instance, ground=not args.no_ground,
                     ground_port=args.ground_port, host=args.host, mavlink_host=args.mavlink_host,
                     control_host=args.control_host,
                     tokens_file=Path(args.tokens) if args.tokens else None, team=args.team,
                     team_loss=args.team_loss, ready_timeout_s=args.ready_timeout,
                     team_key=Path(args.team_key) if args.team_key else None, first_sysid=args.first_sysid,
                     persist=not args.no_persist, platform=Path(args.platform),
                     companion_nice=args.companion_nice,
                     scenario=Path(args.scenario) if args.scenario else None,
                     resume_tasks=args.resume_tasks, tiles=args.tiles,
                     companions_per_process=args.companions_per_process, autopilot=args.autopilot)


def run_up(args: argparse.Namespace) -> int:
    """Start the fleet, print READY and the summary, run until SIGINT/SIGTERM, stop everything."""
    from taskflight_common.runtime import stop_on_signals

    stop = stop_on_signals()
    up = Up(options_from_args(args))
    try:
        up.start(stop)
    except UpError as exc:
        print(f"taskflight up: error: {exc}", file=sys.stderr, flush=True)
        return exc.status
    except KeyboardInterrupt:
        print("taskflight up: interrupted during start-up; everything stopped", file=sys.stderr, flush=True)
        return 130
    print(up.summary(), flush=True)
    try:
        while not stop.wait(0.5):
            dead = first_dead(up.children)
            if dead is not None:
                print(f"taskflight up: {dead.name} exited with status {dead.returncode}; stopping "
                      f"everything. The end of {dead.log_path}:\n{dead.tail()}", file=sys.stderr, flush=True)
                return 1
    finally:
        up.stop()
        print("taskflight up: stopped", flush=True)
    return 0
