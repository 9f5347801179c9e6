"""The command line of one companion host (``taskflight companion-host``, :mod:`companion.host`) that
``taskflight up`` starts for a group of its vehicles: each vehicle's own ``taskflight companion`` options as
one ``--companion`` argument, the options they share once as ``--common``. No secret is on it (``ps``
shows every argument to every user): the control token and the team key's path reach the host through its
environment, as they reach a ``taskflight companion`` process."""

from __future__ import annotations

import shlex
from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar


class Vehicle(Protocol):
    @property
    def sysid(self) -> int: ...


V = TypeVar("V", bound=Vehicle)


def host_name(group: Sequence[Vehicle]) -> str:
    """The host's name in ``taskflight up``'s children and logs: ``companions<first>-<last>`` (system ids)."""
    return f"companions{group[0].sysid}-{group[-1].sysid}"


def host_command(exe: Sequence[str], group: Sequence[V],
                 args_of: Callable[[V], tuple[list[str], list[str]]]) -> tuple[str, list[str]]:
    """``(name, argv)`` of the host running ``group``'s companions; ``args_of(v)`` gives a vehicle's own
    options and those every vehicle shares (the first vehicle's shared ones are used for all)."""
    if not group:
        raise ValueError("a companion host needs at least one vehicle")
    argv = [*exe, "companion-host"]
    for v in group:
        own, _ = args_of(v)
        argv += ["--companion", shlex.join(own)]
    _, common = args_of(group[0])
    return host_name(group), [*argv, "--common", shlex.join(common)]
