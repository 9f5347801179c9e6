"""The team demo's flight figures say what the vertical tracking figure includes.

Found in use: vehicle 1 (the scan-and-search mission) reported a vertical RMS of 1.21 m, the others 0.03 m.
Its mission descends 15 m from the scan altitude at the platform's vertical_speed (2 m/s) while the
autopilot descends at most WPNAV_SPEED_DN (1.5 m/s): the vehicle lags the reference through the
descent. The report now gives the figure per TST node and says why, measured from the flight log."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from taskflight.demo_team import flight_figures


def write_log(path: Path, descent_ref: float, descent_flown: float) -> Path:
    """A flight log: 10 s level at 20 m in node 'scan', then a descent to 5 m in node 'fly-to' with the
    reference at ``descent_ref`` m/s and the vehicle at ``descent_flown`` m/s, both sampled at 20 Hz."""
    rows = [{"type": "header", "t": 0.0, "format": "taskflight-flight-log", "version": 1, "rate_hz": 20.0}]
    t = 0.0
    ref = vehicle = 20.0
    while vehicle > 5.0:
        node = "scan" if t < 10.0 else "fly-to"
        vr = descent_ref if node == "fly-to" and ref > 5.0 else 0.0
        vf = descent_flown if node == "fly-to" else 0.0
        rows.append({"type": "setpoint", "t": round(t, 3), "node": node, "kind": "POSITION",
                     "p": [0.0, 0.0, -ref], "v": [0.0, 0.0, vr]})
        rows.append({"type": "position", "t": round(t, 3), "p": [0.0, 0.0, -vehicle], "v": [0.0, 0.0, vf]})
        t += 0.05
        ref = max(5.0, ref - vr * 0.05)
        vehicle -= vf * 0.05
    path.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    return path


def test_a_descent_the_autopilot_flies_slower_is_named_in_the_report(tmp_path: Path) -> None:
    fig = flight_figures(write_log(tmp_path / "flight1.jsonl", 2.0, 1.5))
    assert fig is not None
    by_node = dict(fig.v_rms_by_node)
    assert by_node["scan"] == pytest.approx(0.0, abs=1e-9)  # level flight: tracked exactly
    assert by_node["fly-to"] > 1.0  # the lag through the descent: where the figure comes from
    text = fig.tracking_text()
    assert "v rms by node: scan 0.00, fly-to" in text
    assert "descended at up to 2.0 m/s, the vehicle at most 1.5 m/s" in text and "WPNAV_SPEED_DN" in text


def test_a_descent_flown_as_asked_needs_no_explanation(tmp_path: Path) -> None:
    fig = flight_figures(write_log(tmp_path / "flight2.jsonl", 1.5, 1.5))
    assert fig is not None and fig.tracking_v_rms < 0.05
    assert "WPNAV_SPEED_DN" not in fig.tracking_text()


def test_a_task_handed_on_is_reported_as_flown_by_its_last_holder_only(tmp_path: Path) -> None:
    """Found on ArduCopter: the team gave the visit to vehicle 2, then to vehicle 3, which flew it; the
    report said "vehicle 2: visit (task 101, done)" as if vehicle 2 had flown it."""
    from taskflight.demo_team import Progress, report
    from taskflight.team_tasking import TaskRow
    from taskflight.up import Up, UpOptions, VehicleInfo

    up = Up(UpOptions(vehicles=3, state_dir=tmp_path))
    up.vehicles = [VehicleInfo(i, i + 1, i, 5760 + 10 * i, 14550 + 10 * i, "") for i in range(3)]
    progress = Progress()
    progress.update([TaskRow(101, "visit", "visit", "assigned", 2)])
    progress.update([TaskRow(101, "visit", "visit", "done", 3)])
    text = report(up, progress)
    assert "vehicle 2: visit (task 101, handed to vehicle 3)" in text, text
    assert "vehicle 3: visit (task 101, done)" in text, text
    assert "101 visit        visit    done       held by vehicle 2, vehicle 3" in text, text
