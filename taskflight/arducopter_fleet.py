"""``taskflight up --autopilot arducopter``: ArduPilot's own copter SITL as the fleet (seed 003 Fig. 1's
lowest tier, the autopilot, as a user who flies ArduPilot has it).

One ArduCopter SITL process per vehicle, as ArduPilot's own SITL swarms run: vehicle i (from 0) is
``-I`` instance I+i and ``--sysid`` K+i, its home east of the model's default home (CMAC) in rows of ten
5 m apart, as :func:`autopilot_model.fleet.fleet_homes` spaces the model's fleet; ``--defaults`` is
ArduPilot's ``copter.parm`` (``../shared/ardupilot/copter.parm`` beside the project, or
``$TASKFLIGHT_ARDUCOPTER_DEFAULTS``), ``-w`` wipes saved parameters, and each runs in a folder of its own,
``<state-dir>/arducopter/instance<N>/`` (it writes ``eeprom.bin`` and ``logs/`` there). Its ports
(``../shared/ardupilot/README.md``): SERIAL0 sends UDP to its companion (``udpclient:``, the companion
listens on 14550+10(I+i) with ``udpin:``), SERIAL1 serves a ground station on TCP 5760+10(I+i) (the
port the model serves, so MAVProxy and QGroundControl connect alike) and SERIAL2 on 5763+10(I+i) is
what ``taskflight up`` itself watches while it starts.

Ready means ready to arm: the EKF uses GPS (EKF_STATUS_REPORT with an absolute horizontal position and
out of constant-position mode, or the STATUSTEXT "EKF3 IMU0 is using GPS"). SYS_STATUS's pre-arm bit is
not enough: it may read healthy while arming is still refused with "Need Position Estimate".
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from taskflight.children import Child
from taskflight_common.geo import home_offset, ned_to_geodetic
from taskflight_common.ports import port_free

log = logging.getLogger(__name__)

BINARY_ENV = "TASKFLIGHT_ARDUCOPTER"
DEFAULTS_ENV = "TASKFLIGHT_ARDUCOPTER_DEFAULTS"
#: the model's default home (CMAC) with its heading; the vehicles stand in rows east of it (home())
HOME = (-35.363261, 149.165230, 584.0, 353.0)
SPACING_M = 5.0
#: EKF_STATUS_REPORT flags (MAVLink EKF_STATUS_FLAGS)
EKF_POS_HORIZ_ABS, EKF_CONST_POS_MODE, EKF_UNINITIALIZED = 0x10, 0x80, 0x400
MSG_EKF_STATUS_REPORT, CMD_SET_MESSAGE_INTERVAL = 193, 511


class ArduCopterError(RuntimeError):
    """ArduCopter SITL cannot be started as asked; the message says why (a usage error: exit 2)."""


def binary() -> str:
    """The ArduCopter SITL binary named by ``$TASKFLIGHT_ARDUCOPTER`` (ArduCopterError if unset or not
    an executable file)."""
    path = os.environ.get(BINARY_ENV, "")
    if not path:
        raise ArduCopterError(f"--autopilot arducopter needs {BINARY_ENV}=/path/to/arducopter (ArduPilot's "
                              "copter SITL binary, built outside the project: see docs/arducopter-sitl.md)")
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        raise ArduCopterError(f"{BINARY_ENV}={path} is not an executable file")
    return path


def defaults_file(root: Path) -> Path:
    """ArduPilot's ``copter.parm``: ``$TASKFLIGHT_ARDUCOPTER_DEFAULTS`` or ``../shared/ardupilot/copter.parm``
    relative to the project ``root`` (ArduCopterError if missing: without it arming fails)."""
    given = os.environ.get(DEFAULTS_ENV)
    path = Path(given) if given else root.parent / "shared" / "ardupilot" / "copter.parm"
    if not path.is_file():
        raise ArduCopterError(f"ArduPilot's copter.parm not found at {path} (set {DEFAULTS_ENV})")
    return path.resolve()


def home(i: int) -> str:
    """Vehicle ``i``'s ``--home LAT,LON,ALT,HDG``: as the model's fleet, SPACING_M apart east of HOME in rows
    of ten, rows SPACING_M south (:func:`taskflight_common.geo.home_offset`)."""
    lat, lon, alt = ned_to_geodetic(HOME[:3], *home_offset(i, SPACING_M), 0.0)
    return f"{lat:.7f},{lon:.7f},{alt:g},{HOME[3]:g}"


def gcs_port(instance: int) -> int:
    """SERIAL1's TCP port, for a ground station (the model's MAVLink TCP port of the same instance)."""
    return 5760 + 10 * instance


def watch_port(instance: int) -> int:
    """SERIAL2's TCP port, which ``taskflight up`` watches until the vehicle is ready."""
    return 5763 + 10 * instance


def ports_taken(base: int, n: int, first_sysid: int, host: str = "127.0.0.1") -> list[str]:
    """The ports SITL opens beyond the model's (SERIAL2, RC input UDP 5501+10i) that are not free."""
    out = []
    for i in range(n):
        who = f"vehicle {i}, sysid {first_sysid + i}"
        if not port_free(socket.SOCK_STREAM, watch_port(base + i), host):
            out.append(f"TCP {watch_port(base + i)} ({who}, ArduCopter SERIAL2)")
        if not port_free(socket.SOCK_DGRAM, 5501 + 10 * (base + i), host):
            out.append(f"UDP {5501 + 10 * (base + i)} ({who}, ArduCopter RC input)")
    return out


def sitl_argv(exe: str, defaults: Path, instance: int, sysid: int, index: int, speedup: float,
              companion_port: int) -> list[str]:
    """One vehicle's ArduCopter SITL command line (module docstring). ``setpriv --pdeathsig`` (when
    there) makes it stop if ``taskflight up`` is killed outright, as every other child does."""
    argv = [exe, "--model", "+", "--speedup", f"{speedup:g}", "--defaults", str(defaults),
            f"-I{instance}", "--sysid", str(sysid), "--home", home(index), "-w",
            "--serial0", f"udpclient:127.0.0.1:{companion_port}", "--serial1", "tcp:0"]
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "TERM", "--", *argv] if setpriv else argv


def start_sitls(exe: str, defaults: Path, state_dir: Path, vehicles: list[Any], speedup: float
                ) -> list[Child]:
    """Start one SITL per vehicle (``vehicles``: :class:`taskflight.up.VehicleInfo`), each in
    ``<state_dir>/arducopter/instance<N>/`` with its output in ``<state_dir>/logs/arducopter<sysid>.log``."""
    out = []
    for v in vehicles:
        folder = state_dir / "arducopter" / f"instance{v.instance}"
        folder.mkdir(parents=True, exist_ok=True)
        argv = sitl_argv(exe, defaults, v.instance, v.sysid, v.index, speedup, v.udp)
        out.append(Child(f"arducopter{v.sysid}", argv, state_dir / "logs" / f"arducopter{v.sysid}.log",
                         cwd=folder).start())
    return out


@dataclass
class _Watched:
    sysid: int
    port: int
    conn: Any = None
    flags: int | None = None
    using_gps: bool = False
    asked_at: float = 0.0


@dataclass
class ReadyWatch:
    """A pymavlink link to each SITL's SERIAL2: asks for EKF_STATUS_REPORT and reads it and the
    STATUSTEXTs until the vehicle's EKF uses GPS. :meth:`poll` never blocks."""

    ports: dict[int, int]
    """SERIAL2 TCP port by system id"""
    _w: dict[int, _Watched] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._w = {s: _Watched(s, p) for s, p in self.ports.items()}

    def poll(self) -> set[int]:
        """Read what has arrived; the system ids whose EKF uses GPS."""
        for w in self._w.values():
            if not w.using_gps:
                self._poll_one(w)
        return {s for s, w in self._w.items() if w.using_gps}

    def _poll_one(self, w: _Watched) -> None:
        os.environ.setdefault("MAVLINK20", "1")
        from pymavlink import mavutil

        if w.conn is None:
            try:
                w.conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{w.port}", source_system=254,
                                                    source_component=191, retries=0)
            except OSError:
                return  # not listening yet
        now = time.monotonic()
        if w.flags is None and now - w.asked_at > 2.0:  # ask (again) for the EKF report at 5 Hz
            w.asked_at = now
            w.conn.mav.command_long_send(w.sysid, 0, CMD_SET_MESSAGE_INTERVAL, 0, MSG_EKF_STATUS_REPORT,
                                         200_000, 0, 0, 0, 0, 0)
        try:
            while (m := w.conn.recv_match(blocking=False)) is not None:
                if m.get_srcSystem() != w.sysid:
                    continue
                t = m.get_type()
                if t == "EKF_STATUS_REPORT":
                    w.flags = int(m.flags)
                    if (w.flags & EKF_POS_HORIZ_ABS
                            and not w.flags & (EKF_CONST_POS_MODE | EKF_UNINITIALIZED)):
                        w.using_gps = True
                elif t == "STATUSTEXT" and "is using GPS" in str(m.text):
                    w.using_gps = True
        except OSError:
            self._close(w)
        if w.using_gps:
            log.debug("vehicle %d: EKF using GPS (flags %s)", w.sysid, w.flags)
            self._close(w)

    def describe(self, sysid: int) -> str:
        """What vehicle ``sysid`` is waiting for, for the progress line."""
        w = self._w[sysid]
        if w.using_gps:
            return "EKF using GPS"
        if w.conn is None:
            return "SITL not answering yet"
        if w.flags is None:
            return "no EKF report yet"
        return f"EKF flags {w.flags:#x}" + (" (constant position mode, no GPS yet)"
                                             if w.flags & EKF_CONST_POS_MODE else "")

    def progress(self, waiting: set[int]) -> str:
        """What the vehicles ``waiting`` wait for, those waiting alike together."""
        alike: dict[str, list[int]] = {}
        for s in sorted(waiting):
            alike.setdefault(self.describe(s), []).append(s)
        return "; ".join(f"vehicle{'s' if len(ids) > 1 else ''} {', '.join(map(str, ids))}: {what}"
                         for what, ids in alike.items())

    @staticmethod
    def _close(w: _Watched) -> None:
        if w.conn is not None:
            with contextlib.suppress(OSError):
                w.conn.close()
            w.conn = None

    def close(self) -> None:
        for w in self._w.values():
            self._close(w)
