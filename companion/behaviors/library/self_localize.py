"""SELF_LOCALIZE (seed 001 Sec. 5.1.2): the recurrent behavior whose situation is a healthy estimate."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..controller import BehaviorExecutionController, Termination, TerminationCause, register


@register
class SelfLocalize(BehaviorExecutionController):
    """Recurrent and active by default; the catalog puts it ``before`` the motion behaviors (Fig. 5's
    SELF_LOCALIZE_BY_VISUAL_MARKERS). The autopilot estimates the state; this behavior watches that
    the estimate stays healthy (the belief ``localization(self, healthy)``, kept by the common belief
    updater from the age of LOCAL_POSITION_NED) and ends with ``wrong_progress`` once it has been
    unhealthy for the catalog's ``performance.unhealthy_s``. It starts again by default when the
    estimate recovers."""

    behavior = "SELF_LOCALIZE"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._bad_since: float | None = None

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return self.need("localization(self, healthy)", "the autopilot's position estimate is not healthy "
                                                        "(needs localization(self, healthy))")

    def on_start(self, params: Mapping[str, Any]) -> None:
        self._bad_since = None

    def performance(self, now_s: float) -> Termination | None:
        if self.ctx.beliefs.holds("localization(self, healthy)"):
            self._bad_since = None
            return None
        if self._bad_since is None:
            self._bad_since = now_s
        grace = self.descriptor.performance.get("unhealthy_s", 1.0)
        if now_s - self._bad_since >= grace:
            return Termination(TerminationCause.WRONG_PROGRESS, "the position estimate is no longer healthy")
        return None
