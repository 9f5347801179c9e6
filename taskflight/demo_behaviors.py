"""``taskflight demo --behaviors``: the demo flight driven by behavior activation requests (seed 001).

The companion runs its executive layer (:class:`companion.behaviors.system.ExecutiveLayer`); the demo is
the *mission requester*: it reads a file of activations in the text form (one per line,
``mission_specs/behaviors_demo.txt``), checks every line against the catalog before flying (a bad
line is reported with its line number and nothing flies), then asks for each in turn and waits for
its end. The report lists each behavior's termination cause and the coordination times (Sec.
7.1.2); ``--timeline PNG`` draws the flight's behavior and process timeline (Fig. 10).
"""

from __future__ import annotations

import logging
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from companion.behaviors.activation import ActivationError, ActivationRequest, parse_activation
from companion.behaviors.system import ExecutiveLayer
from mission_specs import bundled

log = logging.getLogger(__name__)

BEHAVIORS_DEMO = bundled("behaviors_demo.txt")


def load_activations(path: str | Path, layer_check: Callable[[ActivationRequest], object]) -> list[str]:
    """The file's activations (comments and blank lines skipped), each checked; ValueError names file:line."""
    out = []
    for number, line in enumerate(Path(path).read_text(encoding="utf-8").splitlines(), 1):
        text = line.split("#", 1)[0].strip() if not line.lstrip().startswith("#") else ""
        if not text:
            continue
        try:
            layer_check(parse_activation(text, "mission"))
        except ActivationError as exc:
            raise ValueError(f"{path}:{number}: {exc}") from None
        out.append(text)
    if not out:
        raise ValueError(f"{path}: no activations")
    return out


def fly_behaviors(layer: ExecutiveLayer, texts: list[str], deadline_wall: float,
                  gone: Callable[[], bool]) -> tuple[bool, list[str]]:
    """Ask for each activation and wait for its end; (all achieved, report lines)."""
    lines = []
    coordinator = layer.coordinator
    while not coordinator.is_active("SELF_LOCALIZE"):
        if time.monotonic() > deadline_wall or gone():
            return False, ["  gave up waiting for a healthy estimate (SELF_LOCALIZE)"]
        time.sleep(0.05)
    ok = True
    for text in texts:
        result = coordinator.activate(text, "mission")
        if not result.accepted:
            lines.append(f"  {text}: rejected ({result.reason})")
            return False, lines
        log.info("demo: %s (%s)", text, result.activation_id)
        while True:
            ended = next((e for e in coordinator.ended if e.activation_id == result.activation_id), None)
            if ended is not None:
                break
            if time.monotonic() > deadline_wall or gone():
                lines.append(f"  {text}: did not end in time")
                return False, lines
            time.sleep(0.02)
        lines.append(f"  {text}: {ended.cause.value} after {ended.ended_at - ended.started_at:.1f} s"
                     + (f" ({ended.detail})" if ended.detail else ""))
        ok = ok and ended.cause.value == "goal_achieved"
        if not ok:
            break
    tau = [t * 1000 for t in coordinator.coordination_times]
    if tau:
        lines.append(f"  coordination time (Sec. 7.1.2): mean {statistics.mean(tau):.3f} ms, "
                     f"min {min(tau):.3f}, max {max(tau):.3f} ms over {len(tau)} activations")
    return ok, lines
