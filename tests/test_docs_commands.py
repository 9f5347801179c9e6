"""Every command the README and docs/ mark runnable runs as written and exits 0.

The convention (docs/README.md): a fenced block whose info string is ``bash runnable`` holds one
command per line; each is run from the repository root with a deadline and must exit 0, and a trailing
``# expect: TEXT`` also requires TEXT in its output. ``taskflight`` and ``python`` at the start of a
command stand for this checkout's code run by the interpreter running the tests
(``sys.executable -m taskflight.cli``), so the test holds on a clean clone whether or not ``.venv`` is
activated. Commands not marked are checked by hand against ``taskflight ... --help``.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
DEADLINE_S = 60.0
FENCE = re.compile(r"^```bash runnable\s*$\n(.*?)^```\s*$", re.M | re.S)
EXPECT = re.compile(r"#\s*expect:\s*(.+?)\s*$")


def runnable_commands() -> list[tuple[str, str, str | None]]:
    """(page, command, expected text or None) for every line of every ``bash runnable`` block."""
    found = []
    for page in PAGES:
        for block in FENCE.findall(page.read_text(encoding="utf-8")):
            for line in block.splitlines():
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
                expect = EXPECT.search(line)
                found.append((page.relative_to(ROOT).as_posix(), line.strip(),
                              expect.group(1) if expect else None))
    return found


def argv_of(command: str) -> list[str]:
    """The command's words (comments dropped), with ``taskflight`` / ``python`` made this checkout's."""
    words = shlex.split(command, comments=True)
    head = words[0]
    if head in ("taskflight", ".venv/bin/taskflight"):
        return [sys.executable, "-m", "taskflight.cli", *words[1:]]
    if head in ("python", ".venv/bin/python"):
        return [sys.executable, *words[1:]]
    return words


COMMANDS = runnable_commands()


def test_the_docs_mark_some_commands_runnable() -> None:
    pages = {page for page, _, _ in COMMANDS}
    assert "README.md" in pages and len(COMMANDS) >= 5, COMMANDS


@pytest.mark.parametrize(("page", "command", "expect"), COMMANDS,
                         ids=[f"{p}:{c.split('#')[0].strip()}" for p, c, _ in COMMANDS])
def test_runnable_command(page: str, command: str, expect: str | None) -> None:
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, PYTHONPATH=path)
    try:
        done = subprocess.run(argv_of(command), cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=DEADLINE_S, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{page}: `{command}` did not end within {DEADLINE_S:g} s")
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{page}: `{command}` exited {done.returncode}\n{output[-3000:]}"
    if expect is not None:
        assert expect in output, f"{page}: `{command}`: {expect!r} not in its output\n{output[-3000:]}"
