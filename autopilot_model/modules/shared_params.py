"""Parameters read by more than one module, declared in one place (ArduCopter names, units and ranges).

:meth:`ParamStore.define` is idempotent, so each reader calls the function here; the definition (range,
type, default) exists once.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.params import ParamStore


def define_rtl_alt(params: ParamStore) -> None:
    """RTL_ALT: read by the RTL mode and the mission's RETURN_TO_LAUNCH item (ArduCopter: cm, 0 current)."""
    params.define("RTL_ALT", 1500.0, 0.0, 300000.0, "int",
                  "RTL: minimum return altitude above home (cm), 0 = return at the current altitude")
