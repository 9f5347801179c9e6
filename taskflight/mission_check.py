"""``taskflight mission check FILE``: delegation of a mission file, offline (seed 000 Sec. III-A).

Runs :func:`companion.tst.delegation.delegate` against a platform configuration (``--platform YAML``, or
the bundled ``--profile indoor | outdoor``, default indoor; ``--battery PERCENT`` sets the charge left)
and prints either the expanded tree (nodes, waypoints, expected duration, the free parameters fixed) or
each reason of the rejection. Exit codes: 0 accepted, 1 rejected, 2 a bad file (``file:line: field:
reason``). ``--json`` prints :meth:`~companion.tst.delegation.Delegation.to_dict` instead.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Any

from mission_specs import bundled

log = logging.getLogger(__name__)


def add_check_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE",
                        help="the mission YAML: a path, or the name of a bundled mission "
                             "(e.g. scan_and_search.yaml; `taskflight mission list` names them)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--platform", metavar="YAML", help="a platform file (mission_specs/platform_*.yaml)")
    which.add_argument("--profile", choices=("indoor", "outdoor"), default=None,
                       help="a bundled platform (default: indoor)")
    parser.add_argument("--battery", type=float, metavar="PERCENT", default=None,
                        help="battery left, 0-100 %% (default: the platform file's)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run_mission_check(args: argparse.Namespace) -> int:
    from companion.tst.delegation import delegate
    from companion.tst.platform import bundled_platform, load_platform
    from companion.tst.spec import load_mission
    from taskflight_common.yamlio import ConfigError

    try:
        mission = load_mission(mission_path(args.file))
        if args.platform:
            platform = load_platform(args.platform)
        else:
            platform = bundled_platform(args.profile or "indoor")
        if args.battery is not None:
            platform = platform.with_battery(args.battery)
    except (ConfigError, ValueError) as exc:
        print(f"taskflight mission check: error: {exc}", file=sys.stderr)
        return 2
    result = delegate(mission, platform)
    if args.json:
        print(json.dumps(result.to_dict(), indent=1))
    else:
        print(summary(result))
    return 0 if result.accepted else 1


def mission_path(name: str) -> Path:
    """``name`` as given when it is a file; else, for a bare file name, the bundled mission of that name
    (said in the log, so the user knows which file was checked); else the path as given, whose
    absence :func:`~companion.tst.spec.load_mission` reports."""
    path = Path(name)
    if path.is_file() or path.name != name:
        return path
    try:
        found = bundled(name)
    except FileNotFoundError:
        return path
    log.info("no file %s here: checking the bundled mission %s", name, found)
    return found


def bundled_missions() -> list[str]:
    """The names of the bundled missions (the YAML files of :mod:`mission_specs` with a ``mission`` key)."""
    import yaml

    folder = bundled("behavior_catalog.yaml").parent
    names = []
    for path in sorted(folder.glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        if isinstance(data, dict) and "mission" in data:
            names.append(path.name)
    return names


def summary(result: Any) -> str:
    """The text report of a :class:`~companion.tst.delegation.Delegation`."""
    head = (f"mission {result.mission.name} on platform {result.platform}: "
            f"{'ACCEPTED' if result.accepted else 'REJECTED'} ({result.seconds * 1e3:.1f} ms)")
    if not result.accepted:
        return "\n".join([head, *(f"  - {r}" for r in result.reasons)])
    nodes = list(result.mission.root.iter())
    lines = [head, f"  nodes: {len(nodes)} (after expansion), scan waypoints: {result.waypoints}",
             f"  expected duration: {result.expected_s:.1f} s of {result.endurance_s:.1f} s endurance"]
    if result.fixed:
        lines.append("  free parameters fixed: " + ", ".join(f"{k} = {v}" for k, v in result.fixed.items()))
    lines.append("  tree:")
    for node in nodes:
        plan = result.plans.get(str(node.id))
        if node.parent is not None and node.parent.type == "scan-ground":
            continue  # the expanded waypoints: counted on their scan
        text = f"    {'  ' * node.depth()}{node.id} ({node.type})"
        if node.condition:
            text += f" if {node.condition}"
        if plan is not None and node.is_leaf_task:
            bits = []
            if plan.speed_m_s:
                bits.append(f"{plan.speed_m_s:g} m/s")
            if plan.altitude_m is not None:
                bits.append(f"alt {plan.altitude_m:g} m")
            if plan.position_neu is not None:
                bits.append("to ({:.1f}, {:.1f}, {:.1f}) m NEU".format(*plan.position_neu))
            if plan.waypoints_neu:
                bits.append(f"{len(plan.waypoints_neu)} waypoints")
            if plan.length_m:
                bits.append(f"{plan.length_m:.1f} m")
            if plan.expected_s is not None:
                bits.append(f"~{plan.expected_s:.1f} s")
            text += ": " + ", ".join(bits) if bits else ""
        lines.append(text)
    return "\n".join(lines)
