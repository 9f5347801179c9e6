"""The scan-ground executor (seed 000 Sec. VI-E, Fig. 14; Sec. VII break-in, resume, enough)."""

from __future__ import annotations

from typing import Any

from companion.behaviors.activation import format_activation

from .base import TstExecutor, executor


@executor
class ScanGroundExecutor(TstExecutor):
    """Flies the expanded waypoints (delegation's ``expand()``) as one FOLLOW_PATH, so the scan is paused,
    resumed and enoughed as one task. While it runs the camera (if the platform has one) labels its
    detections with the scan's ``data_uuid``. Progress: the waypoint being flown, of how many; after an
    enough, the waypoints skipped.

    ``repeat_flag`` (Fig. 14a: "we are in patrol mode and repeat the scan of the area"): each finished pass
    starts the next one back over the same waypoints in the reverse order (w0 .. wn, wn .. w0, ...; the
    back-and-forth of :func:`~companion.executors.waypoint_order.repeat`), until an enough or an abort
    ends the patrol (seed 003's patrol tasks: "flown back and forth until cancelled")."""

    task = "scan-ground"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.skipped: list[int] = []
        self.lap = 0

    @property
    def repeat(self) -> bool:
        return bool(self.plan.extra.get("repeat"))

    def activation(self) -> str:
        path = [tuple(round(c, 3) for c in w) for w in self.plan.waypoints_neu]
        if self.lap % 2 == 1:
            path.reverse()
        params: dict[str, Any] = {"path": tuple(path)}
        if self.plan.speed_m_s:
            params["speed"] = self.plan.speed_m_s
        return format_activation("FOLLOW_PATH", params)

    def _camera(self) -> Any:
        procs = self.ctx.layer.processes
        return procs.get("camera") if "camera" in procs else None

    def on_start(self) -> None:
        if not self.plan.waypoints_neu:
            raise ValueError(f"{self.node.id}: scan-ground has no waypoints (was it delegated?)")
        camera = self._camera()
        if camera is not None:
            camera.data_uuid = self.plan.extra.get("data_uuid")

    def on_end(self) -> None:
        camera = self._camera()
        if camera is not None:
            camera.data_uuid = None

    def flown(self) -> int:
        act = self.ctx.coordinator.activation("FOLLOW_PATH")
        if act is None or act.activation_id != self.activation_id:
            return self._flown
        self._flown = len(getattr(act.controller, "finished", ()))
        return self._flown

    _flown = 0

    def on_behavior_end(self, ended: Any) -> None:
        if self.repeat and ended.cause.value == "goal_achieved" and not self.finished:
            self.lap += 1
            self._flown = 0
            self.ctx.mark("patrol_lap", node=self.node.id, lap=self.lap)
            self._ask(self.activation())
            return
        super().on_behavior_end(ended)

    def enough_requested(self) -> Any:
        done = self.flown()
        status = super().enough_requested()
        self.skipped = list(range(done, len(self.plan.waypoints_neu)))  # not reached
        self.ctx.mark("scan_enoughed", node=self.node.id, flown=done, skipped=self.skipped)
        return status

    def progress(self) -> dict[str, Any]:
        n = len(self.plan.waypoints_neu)
        done = self.flown() if not self.finished else self._flown
        out: dict[str, Any] = {"waypoint": min(done + 1, n), "waypoints": n,
                               "text": f"waypoint {min(done + 1, n)} of {n}"}
        if self.repeat:
            out["lap"] = self.lap + 1
            out["text"] += f", pass {self.lap + 1}"
        if self.skipped:
            out["skipped"] = self.skipped
        return out
