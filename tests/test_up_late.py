"""``taskflight up``'s start-up deadline: the error names what was not ready and shows the end of the logs
of the processes concerned (the ground service and each late vehicle's companion process), not a
traceback. No processes: :class:`~taskflight.up.Up` with its children's logs written here."""

from __future__ import annotations

from pathlib import Path

from taskflight.children import Child
from taskflight.up import Up, UpError, UpOptions, VehicleInfo


def test_the_late_vehicles_companion_and_the_ground_services_logs_are_shown(tmp_path: Path) -> None:
    up = Up(UpOptions(vehicles=3, state_dir=tmp_path))
    for name, text in (("fleet", "READY\n"), ("companions1-2", "vehicle 2: waiting for the autopilot\n"),
                       ("companions3-3", "vehicle 3 fine\n"), ("ground", "listening\n")):
        (tmp_path / f"{name}.log").write_text(text)
        up.children.append(Child(name, ["true"], tmp_path / f"{name}.log"))
    up._hosted = {"companions1-2": (1, 2), "companions3-3": (3,)}
    up.vehicles = [VehicleInfo(i, i + 1, i, 5760 + 10 * i, 14550 + 10 * i, "") for i in range(3)]
    err = up._late({2}, set(), None)
    assert isinstance(err, UpError)
    text = str(err)
    assert text.startswith("not ready in time: vehicle(s) [2] not heard")
    assert "--- companions1-2:\nvehicle 2: waiting for the autopilot" in text and "--- ground:" in text
    assert "companions3-3" not in text and "--- fleet" not in text
