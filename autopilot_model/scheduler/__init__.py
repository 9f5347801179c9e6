"""Static scheduler of the autopilot model (seed 002: Paparazzi's main loop architecture).

* :mod:`.spec`: module library YAML / dicts (Sec. 3.2, Fig. 3);
* :mod:`.resolve`: two-pass topological sort (Sec. 4.1, Algorithms 1-2);
* :mod:`.offsets`: prescalers and offsets of periodic functions (Sec. 4.3, Fig. 5);
* :mod:`.schedule`: task groups in fixed order and the per-iteration call lists (Sec. 4.2);
* :mod:`.mainloop`: the fixed-frequency main loop; :mod:`.stats`: per-group statistics (Sec. 5).
"""

from .errors import SchedulerError
from .mainloop import MainLoop
from .offsets import (
    HEURISTICS,
    OffsetReport,
    OffsetTask,
    evaluate,
    format_offset_report,
    hyperperiod,
    naive_offsets,
    offset_report,
    optimised_offsets,
    zero_offsets,
)
from .resolve import Resolution, resolve_modules
from .schedule import FunctionRef, PeriodicCall, Schedule, build_schedule
from .spec import (
    EVENTS_GROUP,
    TASK_GROUPS,
    ModulesConfig,
    ModuleSpec,
    PeriodicSpec,
    load_modules,
    parse_modules,
)
from .stats import STAT_GROUPS, DutyWindow, SchedulerStats

__all__ = [
    "EVENTS_GROUP",
    "HEURISTICS",
    "STAT_GROUPS",
    "TASK_GROUPS",
    "DutyWindow",
    "FunctionRef",
    "MainLoop",
    "ModuleSpec",
    "ModulesConfig",
    "OffsetReport",
    "OffsetTask",
    "PeriodicCall",
    "PeriodicSpec",
    "Resolution",
    "Schedule",
    "SchedulerError",
    "SchedulerStats",
    "build_schedule",
    "evaluate",
    "format_offset_report",
    "hyperperiod",
    "load_modules",
    "naive_offsets",
    "offset_report",
    "optimised_offsets",
    "parse_modules",
    "resolve_modules",
    "zero_offsets",
]
