"""Command protocol: COMMAND_LONG and COMMAND_INT in, exactly one COMMAND_ACK out per command.

Handlers are registered per MAV_CMD with :meth:`CommandDispatcher.add`; each gets a normalised
:class:`Command` and returns ``(MAV_RESULT, reason)``. A DENIED or FAILED result with a reason is also
announced by STATUSTEXT, as ArduPilot does for pre-arm failures. A command nobody handles is answered
UNSUPPORTED. A handler that raises :class:`~.endpoint.InvalidFieldError` (NaN where a number is needed ...)
gets DENIED, and nothing is changed.

Retransmissions are acted on once. A ground station that gets no ACK sends the same command again,
MAVSDK and QGC with ``confirmation`` incremented, pymavlink scripts often identically. A command from
the same sender (link, system, component) with the same id and parameters as the previous one is a
retransmission if its ``confirmation`` is greater than zero (within :attr:`CommandDispatcher.retry_window_s`)
or if it arrives within :attr:`CommandDispatcher.dup_window_s`: it is answered with the stored result
and not executed again. Only an *accepted* command is remembered this way: a refused one changed
nothing, so sending it again (e.g. arming after the reason for the refusal went away) re-evaluates it.
The windows are wall time on purpose: retransmission is a property of the
link and the client's timers, which run on the wall clock, not of simulated time (ArduCopter has no such
windows: it executes every retransmission; see ``docs/conformance.md``, "Time bases"). Commands that are
harmless to repeat (requests for messages, intervals) are never deduplicated.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from .endpoint import InvalidFieldError

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .transport import Peer

log = logging.getLogger(__name__)

ACCEPTED = mavlink2.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink2.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink2.MAV_RESULT_DENIED
UNSUPPORTED = mavlink2.MAV_RESULT_UNSUPPORTED
FAILED = mavlink2.MAV_RESULT_FAILED

CommandResult = tuple[int, str | None]


@dataclass
class Command:
    """One received command, whichever message carried it.

    ``params`` are param1..param7. For COMMAND_INT, param5/param6 are ``x``/``y`` converted to
    degrees when the frame is global (``x_int``/``y_int`` keep the raw integers) and param7 is ``z``.
    """

    command: int
    params: tuple[float, ...]
    src_system: int
    src_component: int
    confirmation: int = 0
    frame: int | None = None  # COMMAND_INT only
    is_int: bool = False
    x_int: int = 0
    y_int: int = 0

    def p(self, i: int) -> float:
        """param i (1-based)."""
        return self.params[i - 1]

    def finite(self, i: int, what: str | None = None) -> float:
        """param i, which must be a finite number (else the command is denied as invalid)."""
        v = self.params[i - 1]
        if not math.isfinite(v):
            raise InvalidFieldError(f"{what or f'param{i}'} must be a number")
        return v

    def key(self) -> tuple[Any, ...]:
        # NaN != NaN: compare parameters by their text so NaN-filled retransmissions match
        return (self.command, self.frame, tuple(repr(p) for p in self.params))


CommandHandler = Callable[[Command, "Peer"], CommandResult]

GLOBAL_INT_FRAMES = frozenset({
    mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_FRAME_GLOBAL_INT, mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
})


@dataclass
class _Recent:
    key: tuple[Any, ...]
    wall: float
    result: int


@dataclass
class CommandDispatcher:
    """MAV_CMD handler table, ACKs, STATUSTEXT reasons and deduplication."""

    endpoint: MavlinkEndpoint
    dup_window_s: float = 0.5
    retry_window_s: float = 5.0
    wall: Callable[[], float] = time.monotonic
    table: dict[int, CommandHandler] = field(default_factory=dict)
    no_dedup: set[int] = field(default_factory=set)
    _recent: dict[tuple[Any, ...], _Recent] = field(default_factory=dict)
    _after_ack: list[Callable[[], object]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.endpoint.add_handler("COMMAND_LONG", self._on_command_long)
        self.endpoint.add_handler("COMMAND_INT", self._on_command_int)

    def add(self, command: int, fn: CommandHandler, dedup: bool = True) -> None:
        """Handle MAV_CMD ``command`` with ``fn(cmd, link) -> (MAV_RESULT, reason or None)``."""
        self.table[command] = fn
        if not dedup:
            self.no_dedup.add(command)

    def after_ack(self, fn: Callable[[], object]) -> None:
        """Run ``fn`` right after the ACK of the command being handled has been sent."""
        self._after_ack.append(fn)

    # --- message handlers ----------------------------------------------------------------------
    def _on_command_long(self, msg: Any, peer: Peer) -> None:
        cmd = Command(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5,
                                    msg.param6, msg.param7),
                      msg.get_srcSystem(), msg.get_srcComponent(), confirmation=msg.confirmation)
        self.dispatch(cmd, peer)

    def _on_command_int(self, msg: Any, peer: Peer) -> None:
        if msg.frame in GLOBAL_INT_FRAMES:
            x, y = msg.x * 1e-7, msg.y * 1e-7
        else:
            x, y = float(msg.x), float(msg.y)
        cmd = Command(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, x, y, msg.z),
                      msg.get_srcSystem(), msg.get_srcComponent(), frame=msg.frame, is_int=True,
                      x_int=msg.x, y_int=msg.y)
        self.dispatch(cmd, peer)

    # --- dispatch ------------------------------------------------------------------------------
    def dispatch(self, cmd: Command, peer: Peer) -> int:
        """Execute (or recognise as a retransmission) and acknowledge one command; returns the result."""
        ep = self.endpoint
        ep.stats["commands"] += 1
        fn = self.table.get(cmd.command)
        if fn is None:
            ep.stats["commands_unsupported"] += 1
            self._ack(cmd, UNSUPPORTED, peer)
            return UNSUPPORTED
        sender = (peer.name, cmd.src_system, cmd.src_component, cmd.command)
        now = self.wall()
        if cmd.command not in self.no_dedup:
            prev = self._recent.get(sender)
            if prev is not None and prev.result == ACCEPTED and prev.key == cmd.key():
                age = now - prev.wall
                if (cmd.confirmation > 0 and age < self.retry_window_s) or age < self.dup_window_s:
                    ep.stats["commands_duplicate"] += 1
                    prev.wall = now
                    self._ack(cmd, prev.result, peer)
                    return prev.result
        self._after_ack.clear()
        try:
            result, reason = fn(cmd, peer)
        except InvalidFieldError as exc:
            ep.stats["invalid_field"] += 1
            result, reason = DENIED, f"{_name(cmd.command)}: {exc}"
            self._after_ack.clear()
        except Exception:
            ep.stats["handler_error"] += 1
            log.exception("command %s failed", _name(cmd.command))
            result, reason = FAILED, None
            self._after_ack.clear()
        if reason and result in (DENIED, FAILED, TEMPORARILY_REJECTED):
            ep.statustext(mavlink2.MAV_SEVERITY_WARNING, reason, None)
        self._ack(cmd, result, peer)
        if len(self._recent) > 256:
            self._recent.clear()
        self._recent[sender] = _Recent(cmd.key(), now, result)
        pending, self._after_ack = self._after_ack, []
        for f in pending:
            f()
        return result

    def _ack(self, cmd: Command, result: int, peer: Peer) -> None:
        ep = self.endpoint
        ep.stats[f"ack_{result}"] += 1
        ep.send(ep.mav.command_ack_encode(cmd.command, result, 0, 0, cmd.src_system, cmd.src_component), peer)


def _name(command: int) -> str:
    entry = mavlink2.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {command}"
