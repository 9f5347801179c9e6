"""Errors of the static scheduler.

Configuration syntax problems are :class:`taskflight_common.yamlio.ConfigError` (file, line, field, reason);
problems found while resolving the dependency graph (seed 002 Sec. 4.1, Algorithms 1-2) or binding
function names are :class:`SchedulerError`.
"""

from __future__ import annotations


class SchedulerError(ValueError):
    """The module selection cannot be scheduled: cycle, conflict, unmet dependency, missing function.

    The message names what is wrong and where (module name and, when known, ``file:line``).
    """
