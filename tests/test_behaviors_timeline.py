"""The Fig. 10 timeline (seed 001 Sec. 7.1.2-7.1.3) from a flight log, through the CLI."""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import pytest

from companion.behaviors.timeline import (
    TimelineError,
    intervals,
    load_log,
    plot_timeline,
    read_log,
    rejected_requests,
)
from taskflight.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# Fig. 10's opening: GO_TO_POINT starts the motion controller and the trajectory planner; when it ends
# the planner stops but the motion controller keeps running into SEARCH_FRAME (the delayed stop).
LOG: list[dict[str, Any]] = [
    {"t": 0.95, "type": "request", "event": "accepted", "behavior": "GO_TO_POINT", "requester": "mission"},
    {"t": 1.0, "type": "behavior", "event": "started", "behavior": "GO_TO_POINT", "activation_id": "a1",
     "requester": "mission", "params": {"coordinate": [10, 0, 5]}},
    {"t": 1.0, "type": "process", "event": "start", "process": "motion_controller", "by": "GO_TO_POINT"},
    {"t": 1.0, "type": "process", "event": "start", "process": "trajectory_planner", "by": "GO_TO_POINT"},
    {"t": 4.0, "type": "request", "event": "rejected", "behavior": "LAND", "requester": "mission",
     "reason": "GO_TO_POINT has priority"},
    {"t": 9.0, "type": "behavior", "event": "terminated", "behavior": "GO_TO_POINT", "activation_id": "a1",
     "cause": "goal_achieved"},
    {"t": 9.0, "type": "behavior", "event": "started", "behavior": "SEARCH_FRAME", "activation_id": "a2",
     "requester": "mission"},
    {"t": 9.0, "type": "process", "event": "stop", "process": "trajectory_planner", "by": "GO_TO_POINT"},
    {"t": 15.5, "type": "behavior", "event": "terminated", "behavior": "SEARCH_FRAME", "activation_id": "a2",
     "cause": "time_out"},
    {"t": 15.5, "type": "behavior", "event": "started", "behavior": "GO_TO_POINT", "activation_id": "a3",
     "requester": "mission"},
    {"t": 15.5, "type": "process", "event": "start", "process": "trajectory_planner", "by": "GO_TO_POINT"},
    {"t": 21.0, "type": "telemetry", "event": "whatever"},  # unknown type: skipped
    {"t": 22.0, "type": "process", "event": "pause", "process": "motion_controller"},  # unknown event
    {"t": 25.0, "type": "behavior", "event": "terminated", "behavior": "GO_TO_POINT", "activation_id": "a3",
     "cause": "wrong_progress"},
    {"t": 25.0, "type": "behavior", "event": "started", "behavior": "KEEP_HOVERING", "activation_id": "a4",
     "requester": "default"},
    {"t": 30.0, "type": "process", "event": "stop", "process": "trajectory_planner", "by": "GO_TO_POINT"},
]


def _write(path: Path, lines: list[Any]) -> Path:
    path.write_text("".join((x if isinstance(x, str) else json.dumps(x)) + "\n" for x in lines))
    return path


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, "not a PNG"
    assert data[12:16] == b"IHDR"
    assert data[-8:-4] == b"IEND", "truncated PNG"
    return struct.unpack(">II", data[16:24])


def test_intervals_show_the_delayed_stop(tmp_path: Path) -> None:
    tl = load_log(_write(tmp_path / "flight.jsonl", LOG))
    assert tl.skipped == 2
    bars = intervals(tl.events)
    beh = [(iv.name, iv.start, iv.end, iv.cause, iv.open) for iv in bars if iv.kind == "behavior"]
    assert beh == [
        ("GO_TO_POINT", 1.0, 9.0, "goal_achieved", False),
        ("SEARCH_FRAME", 9.0, 15.5, "time_out", False),
        ("GO_TO_POINT", 15.5, 25.0, "wrong_progress", False),
        ("KEEP_HOVERING", 25.0, 30.0, None, True),  # still active: ends at the log's last time
    ]
    procs = [(iv.name, iv.start, iv.end, iv.open) for iv in bars if iv.kind == "process"]
    # the motion controller runs unbroken across GO_TO_POINT -> SEARCH_FRAME -> GO_TO_POINT
    assert procs == [
        ("motion_controller", 1.0, 30.0, True),
        ("trajectory_planner", 1.0, 9.0, False),
        ("trajectory_planner", 15.5, 30.0, False),
    ]
    assert bars[0].requester == "mission" and bars[0].activation_id == "a1"
    assert [r["behavior"] for r in rejected_requests(tl.events)] == ["LAND"]


def test_events_are_sorted_and_pair_by_activation(tmp_path: Path) -> None:
    # two writers interleave: a line may come out of time order; two activations of one behavior overlap
    lines = [
        {"t": 2.0, "type": "behavior", "event": "started", "behavior": "ROTATE", "activation_id": "r2"},
        {"t": 1.0, "type": "behavior", "event": "started", "behavior": "ROTATE", "activation_id": "r1"},
        {"t": 5.0, "type": "behavior", "event": "terminated", "behavior": "ROTATE", "activation_id": "r1",
         "cause": "interrupted"},
        {"t": 4.0, "type": "behavior", "event": "terminated", "behavior": "ROTATE", "activation_id": "r2",
         "cause": "goal_achieved"},
        {"t": 6.0, "type": "process", "event": "stop", "process": "yaw_controller"},  # stop without start
    ]
    bars = intervals(read_log(_write(tmp_path / "log.jsonl", lines)))
    assert [(iv.activation_id, iv.start, iv.end, iv.cause) for iv in bars if iv.kind == "behavior"] == [
        ("r1", 1.0, 5.0, "interrupted"), ("r2", 2.0, 4.0, "goal_achieved")]
    assert [(iv.name, iv.start, iv.end) for iv in bars if iv.kind == "process"] == [
        ("yaw_controller", 1.0, 6.0)]
    assert intervals([]) == []


@pytest.mark.parametrize("bad, fragment", [
    ('{"t": 1.0, "type": "behavior", "event": "started"', "malformed JSON"),
    ('{"t": "soon", "type": "process", "event": "start", "process": "p"}', "field 't'"),
    ('{"t": 1.0, "type": "behavior", "event": "started"}', "without a 'behavior' name"),
    ('{"t": 1.0, "type": "process", "event": "stop", "process": ""}', "without a 'process' name"),
])
def test_malformed_line_names_file_and_line(tmp_path: Path, bad: str, fragment: str) -> None:
    path = _write(tmp_path / "bad.jsonl", [LOG[0], "", bad, LOG[1]])
    with pytest.raises(TimelineError) as err:
        read_log(path)
    assert f"{path}:3:" in str(err.value) and fragment in str(err.value)


def test_cli_draws_the_timeline(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _write(tmp_path / "flight.jsonl", LOG)
    out = tmp_path / "fig10.png"
    rc = main(["behaviors", "timeline", str(log), "--out", str(out), "--title", "Experiment 6"])
    assert rc == 0
    w, h = _png_size(out)
    assert 600 <= w <= 2000 and 200 <= h <= 1500, (w, h)
    assert out.stat().st_size > 5000  # bars, labels and text, not an empty canvas
    printed = capsys.readouterr().out
    assert "4 behavior activation(s), 3 process execution(s), 2 line(s) skipped" in printed


def test_cli_reports_a_bad_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _write(tmp_path / "bad.jsonl", [LOG[0], "{not json"])
    out = tmp_path / "x.png"
    assert main(["behaviors", "timeline", str(log), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{log}:2: malformed JSON" in err and not out.exists()
    assert main(["behaviors", "timeline", str(tmp_path / "missing.jsonl"), "--out", str(out)]) == 2
    assert not out.exists()


def test_cli_needs_out(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["behaviors", "timeline", "log.jsonl"])
    assert exc.value.code == 2 and "--out" in capsys.readouterr().err


def test_plot_grows_with_rows_and_handles_no_events(tmp_path: Path) -> None:
    small = plot_timeline(LOG[:3], tmp_path / "small.png")
    many = [{"t": float(i), "type": "process", "event": "start", "process": f"p{i}"} for i in range(20)]
    big = plot_timeline(many, tmp_path / "big.png", title="twenty processes")
    assert _png_size(big)[1] > _png_size(small)[1]
    empty = plot_timeline([], tmp_path / "empty.png")
    assert _png_size(empty)[0] > 0
