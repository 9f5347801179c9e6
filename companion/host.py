"""``taskflight companion-host``: K vehicles' companions in one process (a simulated fleet's companions).

Each hosted companion is the companion ``taskflight companion`` runs on a real vehicle, made by the same
code (:func:`companion.main.config_from_args` from that command's own options, then
:func:`companion.builder.build_companion`): its own queue, executive layer, missions, team member, MAVLink
link and control surface (or fleet-bus presence). What the host shares is the process: one interpreter,
the imported modules (pymavlink's dialects, FastAPI, scipy: ~100 MB of a companion process's ~140 MB),
one garbage collector with the start-up heap frozen once, one signal handler; a simulated fleet of N
vehicles needs N/K processes instead of N.

    taskflight companion-host --companion "--autopilot udpout:127.0.0.1:14550 --control-port 0" \\
                              --companion "--autopilot udpout:127.0.0.1:14560 --control-port 0" \\
                              [--common "--team udp://239.255.70.1:14650 --platform P.yaml"]
    taskflight companion-host --config FILE

``FILE`` is YAML ``{common: [ARG, ...], companions: [[ARG, ...], ...]}`` (or a string per entry, split as
a shell would): ``common`` is appended to every companion's own arguments. A bad option or file of any
companion exits with status 2 naming the companion (``companion 2 (--autopilot ...)``) before any starts.
The companions start together (each waits for its own autopilot), ``SIGINT``/``SIGTERM`` closes them all
(in parallel, each as :meth:`Companion.close` does); a companion that cannot start (its mission rejected,
its control port taken) stops the host with status 1, the others closed.
"""

from __future__ import annotations

import argparse
import logging
import shlex
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

from taskflight_common.yamlio import ConfigError

if TYPE_CHECKING:
    from companion.builder import Companion, CompanionConfig

log = logging.getLogger(__name__)

#: companions started at once: each waits for its autopilot, but also builds its control surface's app
#: (~0.4 s of CPU) and has ``ControlServer.start``'s 10 s to get its server up: 25 at once under one
#: interpreter's lock on a loaded machine missed that deadline
START_PARALLEL = 4
#: companions closed at once (each mostly waits for its own threads to end)
CLOSE_PARALLEL = 64


class HostConfigError(ValueError):
    """The host's configuration (or one companion's options) is wrong; the message names which."""


def add_host_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``taskflight companion-host``."""
    parser.add_argument("--config", default=None, metavar="YAML",
                        help="{common: [ARG, ...], companions: [[ARG, ...], ...]}: each entry one "
                             "companion's 'taskflight companion' options, common ones appended to each")
    parser.add_argument("--companion", action="append", default=[], metavar="ARGS",
                        help="one companion's 'taskflight companion' options, quoted as one argument "
                             "(repeat for each vehicle)")
    parser.add_argument("--common", default="", metavar="ARGS",
                        help="options appended to every companion's (e.g. the team URL, the platform)")


def _arg_list(value: Any, where: str) -> list[str]:
    if isinstance(value, str):
        return shlex.split(value)
    if isinstance(value, list) and all(isinstance(a, (str, int, float)) for a in value):
        return [str(a) for a in value]
    raise HostConfigError(f"{where}: expected a list of arguments or one string, got {type(value).__name__}")


def argument_sets(args: argparse.Namespace) -> list[list[str]]:
    """Every companion's argument list, ``--config`` first then each ``--companion``, common ones appended
    (:class:`HostConfigError` naming the file or field if it is wrong)."""
    common = shlex.split(args.common or "")
    sets: list[list[str]] = []
    if args.config:
        import yaml

        path = Path(args.config)
        try:
            doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as exc:
            raise HostConfigError(f"--config {path}: {exc}") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("companions"), list):
            raise HostConfigError(f"{path}: companions: expected a list of argument lists")
        unknown = set(doc) - {"common", "companions"}
        if unknown:
            raise HostConfigError(f"{path}: unknown field(s) {sorted(unknown)} (common, companions)")
        file_common = _arg_list(doc.get("common", []), f"{path}: common")
        sets += [_arg_list(c, f"{path}: companions[{i}]") + file_common
                 for i, c in enumerate(doc["companions"])]
    sets += [shlex.split(c) for c in args.companion]
    if not sets:
        raise HostConfigError("no companion: give --config FILE or --companion ARGS (one per vehicle)")
    return [s + common for s in sets]


def configs_from_sets(sets: Sequence[Sequence[str]]) -> list[CompanionConfig]:
    """Each argument set through ``taskflight companion``'s own parser and :func:`config_from_args`
    (:class:`HostConfigError` naming the companion and its option or file)."""
    from companion.main import add_companion_arguments, config_from_args

    parser = argparse.ArgumentParser(prog="taskflight companion", add_help=False, exit_on_error=False)
    add_companion_arguments(parser)
    out = []
    for i, argv in enumerate(sets, 1):
        label = f"companion {i} ({' '.join(argv[:2])})"
        try:
            out.append(config_from_args(parser.parse_args(list(argv))))
        except argparse.ArgumentError as exc:
            raise HostConfigError(f"{label}: {exc}") from None
        except SystemExit:  # a required option missing: argparse exits even with exit_on_error=False
            raise HostConfigError(f"{label}: missing a required option (--autopilot URL)") from None
        except (ConfigError, ValueError, OSError) as exc:
            raise HostConfigError(f"{label}: {exc}") from None
    ports = [c.control_port for c in out if c.control_port]
    if len(ports) != len(set(ports)):
        raise HostConfigError(f"two companions on one control port: {sorted(ports)} (give each its own, "
                              "or 0)")
    return out


class CompanionHost:
    """K companions in one process (module docstring): :meth:`start` starts them together and returns once
    all are started, :meth:`close` closes them all."""

    def __init__(self, configs: Sequence[CompanionConfig]) -> None:
        from companion.builder import build_companion

        self.companions: list[Companion] = []
        try:
            for c in configs:
                self.companions.append(build_companion(c))
        except BaseException:
            self.close()
            raise

    def start(self, stop: threading.Event | None = None) -> CompanionHost:
        """Start every companion, :data:`START_PARALLEL` at a time (each waits for its own autopilot); once
        one fails, those not yet started are not started, and the first error (``MissionRejectedError``,
        ``OSError``, ``RuntimeError``) is raised when the others have returned (:meth:`close` closes
        all)."""
        stop = stop or threading.Event()
        if not self.companions:
            return self
        with ThreadPoolExecutor(max_workers=min(START_PARALLEL, len(self.companions)),
                                thread_name_prefix="host-start") as pool:
            failed = threading.Event()

            def start(c: Companion) -> None:
                if stop.is_set() or failed.is_set():
                    return
                try:
                    c.start(stop)
                except BaseException:
                    failed.set()
                    raise

            futures = [pool.submit(start, c) for c in self.companions]
            errors = [f.exception() for f in futures]
        first = next((e for e in errors if e is not None), None)
        if first is not None:
            raise first
        log.info("companion host: %d companions started", len(self.companions))
        return self

    def close(self) -> None:
        """Close every companion (in parallel: each waits for its own threads)."""
        if not self.companions:
            return
        with ThreadPoolExecutor(max_workers=min(CLOSE_PARALLEL, len(self.companions)),
                                thread_name_prefix="host-close") as pool:
            for f in [pool.submit(c.close) for c in self.companions]:
                if (exc := f.exception()) is not None:
                    log.warning("closing a companion: %s", exc)
        self.companions = []

    def __enter__(self) -> CompanionHost:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_host(args: argparse.Namespace) -> int:
    """Run until SIGINT/SIGTERM; 2 for bad options or files, 1 if a companion could not start."""
    from companion.main import serve

    try:
        host = CompanionHost(configs_from_sets(argument_sets(args)))
    except (HostConfigError, ConfigError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    return serve(host, f"companion host ({len(host.companions)} companions)")
