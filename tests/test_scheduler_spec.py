"""Module library parsing (seed 002 Sec. 3.2, Fig. 3): YAML and dicts, errors naming file, line, field."""

from __future__ import annotations

from pathlib import Path

import pytest

from autopilot_model.scheduler import load_modules, parse_modules
from taskflight_common.yamlio import ConfigError

FIXTURES = Path(__file__).parent / "fixtures"


def test_fig3_fixture_parses() -> None:
    cfg = load_modules(FIXTURES / "scheduler_fig3.yaml")
    assert cfg.main_loop_hz == 500 and cfg.period_us == 2000
    assert cfg.select == ("example", "module3")
    ex = cfg.modules["example"]
    assert ex.task_group == "control"
    assert ex.depends == (("module1",), ("module2", "module3"), ("@func1",))
    assert ex.provides == ("@func2",)          # '@' added when omitted, as in Fig. 3's <provides>
    assert ex.conflicts == ("module4", "@func3")
    assert ex.where.endswith("scheduler_fig3.yaml:4")
    m5 = cfg.modules["module5"]
    (p,) = m5.periodic
    assert (p.function, p.freq, p.prescaler, p.offset) == ("module5.periodic", 10, 50, 7)
    assert cfg.modules["module3"].event == ("module3.event",)


def test_dict_input_and_defaults() -> None:
    cfg = parse_modules({"modules": [
        {"name": "a", "task_group": "core", "depends": ["b", "c|@f"],
         "periodic": [{"function": "a.p"}, {"function": "a.slow", "freq": 0.5, "cost": 12.5}]},
    ]})
    a = cfg.modules["a"]
    assert cfg.main_loop_hz == 500 and cfg.select == ()
    assert a.depends == (("b",), ("c", "@f"))
    fast, slow = a.periodic
    assert fast.freq == 500 and fast.prescaler == 1 and fast.offset is None and fast.cost is None
    assert slow.prescaler == 1000 and slow.cost == 12.5


def test_fractional_frequencies_are_exact() -> None:
    cfg = parse_modules({"main_loop_hz": 1000, "modules": [
        {"name": "a", "task_group": "core", "periodic": [{"function": "f", "freq": 0.1},
                                                          {"function": "g", "freq": 12.5}]}]})
    assert [p.prescaler for p in cfg.modules["a"].periodic] == [10000, 80]


def test_dict_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match=r"^<dict>: modules\[0\]\.periodic\[0\]\.freq: 7 Hz does not"):
        parse_modules({"modules": [{"name": "a", "task_group": "core",
                                    "periodic": [{"function": "f", "freq": 7}]}]})


P = pytest.param
HEADER = "main_loop_hz: 500\nmodules:\n"
GOOD = "  - name: imu\n    task_group: sensors\n    periodic:\n      - {function: imu.p, freq: 100}\n"

# (yaml text, line, field, reason fragment); lines are 1-based in the text.
BASE = HEADER + GOOD   # 6 lines: an appended line is line 7
CASES = [
    P(HEADER + "  - name: imu\n    task_group: sensor\n", 4, "modules[0].task_group",
      "must be one of sensors, estimation", id="unknown-task-group"),
    P(BASE + "      - {function: imu.q, freq: 300}\n", 7, "modules[0].periodic[1].freq",
      "300 Hz does not divide the main loop frequency 500 Hz", id="freq-not-dividing"),
    P(BASE + "    dependz: ahrs\n", 7, "modules[0].dependz", "unknown field", id="unknown-module-key"),
    P(BASE + "      - {function: imu.q, freq: 5, ofset: 2}\n", 7, "modules[0].periodic[1].ofset",
      "unknown field", id="unknown-periodic-key"),
    P(BASE + "      - {function: imu.q, freq: fast}\n", 7, "modules[0].periodic[1].freq",
      "expected a number", id="freq-not-a-number"),
    P(BASE + "      - {function: imu.q, freq: 100, offset: 1.5}\n", 7, "modules[0].periodic[1].offset",
      "expected an integer", id="offset-not-integer"),
    P(BASE + "      - {function: imu.q, freq: 100, offset: 5}\n", 7, "modules[0].periodic[1].offset",
      "out of range: must be in [0, 4]", id="offset-out-of-range"),
    P(BASE + "      - {function: imu.q, freq: 100, cost: -1}\n", 7, "modules[0].periodic[1].cost",
      "must be >= 0", id="negative-cost"),
    P(BASE + "      - {function: imu.p, freq: 50}\n", 7, "modules[0].periodic[1].function",
      "listed twice", id="duplicate-function"),
    P(BASE + "  - name: imu\n    task_group: core\n", 7, "modules[1].name",
      "duplicate module name 'imu' (first defined at", id="duplicate-module"),
    P(BASE + "    depends: 'a,,b'\n", 7, "modules[0].depends", "invalid name ''", id="bad-depends"),
    P(BASE + "    depends: 'imu'\n", 7, "modules[0].depends", "depends on itself", id="self-dependency"),
    P(BASE + "    conflicts: 'a|b'\n", 7, "modules[0].conflicts", "'|' (OR) is not allowed",
      id="or-in-conflicts"),
    P(BASE + "    depends: 12\n", 7, "modules[0].depends", "expected a string", id="depends-wrong-type"),
    P(BASE + "    event: imu.poll\n", 7, "modules[0].event", "expected a list", id="event-not-a-list"),
    P(BASE + "    init: [imu.init, 3]\n", 7, "modules[0].init[1]", "expected a non-empty name",
      id="init-item-type"),
    P(HEADER + "  - name: 'bad name'\n    task_group: core\n", 3, "modules[0].name",
      "invalid module name", id="bad-module-name"),
    P(HEADER + "  - task_group: core\n", 3, "modules[0]", "missing required field 'modules[0].name'",
      id="missing-name"),
    P(BASE + "select:\n  - imu\n  - gps\n", 9, "select[1]", "unknown module 'gps'", id="select-unknown"),
    P(BASE + "select: [imu, imu]\n", 7, "select[1]", "selected twice", id="select-twice"),
    P("main_loop_hz: 512\nmodules:\n" + GOOD, 1, "main_loop_hz", "does not give an integer period",
      id="main-loop-period"),
    P("main_loop_hz: -5\nmodules: []\n", 1, "main_loop_hz", "must be > 0", id="main-loop-negative"),
    P(BASE + "selection: [imu]\n", 7, "selection", "unknown field", id="unknown-top-key"),
    P("main_loop_hz: 500\nmodules: {imu: 1}\n", 2, "modules", "expected a list", id="modules-type"),
]


@pytest.mark.parametrize(("text", "line", "field", "reason"), CASES)
def test_yaml_errors_name_file_line_field(tmp_path: Path, text: str, line: int, field: str,
                                          reason: str) -> None:
    path = tmp_path / "modules.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_modules(path)
    err = info.value
    msg = str(err)
    assert msg.startswith(f"{path}:{line}: {field}: "), msg
    assert reason in msg, msg
    assert (err.file, err.line, err.field) == (str(path), line, field)


def test_yaml_syntax_error_has_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(HEADER + GOOD + "    event: [a, b\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml:\d+: YAML syntax error"):
        load_modules(path)
