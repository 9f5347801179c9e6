"""Taskflight installs as a package: a wheel (not an editable install) carries its bundled files.

The wheel is built from this checkout and installed with no dependencies into a fresh virtual
environment whose dependencies come from the test environment's site-packages (a ``.pth`` line: its own
``.pth`` files, among them the editable install's finder, are not processed there). Then, from a folder
outside the checkout, ``taskflight mission check`` checks a bundled mission by name and ``taskflight demo``
flies, and every project package is imported from the fresh environment, not from the checkout.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("taskflight", "taskflight_common", "mission_specs", "autopilot_model", "companion",
            "groundstation")

pytestmark = [pytest.mark.slow, pytest.mark.integration]


def _run(argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout,
                          check=False)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The fresh environment's ``bin`` folder, with the wheel of this checkout installed."""
    work = tmp_path_factory.mktemp("wheel")
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"),
                  str(ROOT)], cwd=work, timeout=600)
    if built.returncode != 0:
        if "No matching distribution" in built.stderr or "Could not find a version" in built.stderr:
            pytest.skip("the build backend could not be installed (no package registry?): "
                        + built.stderr[-300:])
        pytest.fail(f"pip wheel failed:\n{built.stdout}\n{built.stderr}")
    wheels = list((work / "dist").glob("taskflight-*.whl"))
    assert len(wheels) == 1, wheels
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    where = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = Path(_run([str(venv / "bin" / "python"), "-c", where], cwd=work, timeout=60).stdout.strip())
    (site / "_taskflight_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    done = _run([str(venv / "bin" / "python"), "-m", "pip", "install", "--no-deps", "-q", str(wheels[0])],
                cwd=work, timeout=300)
    assert done.returncode == 0, done.stderr
    return venv / "bin"


def test_the_wheel_imports_from_its_own_environment(installed: Path, tmp_path: Path) -> None:
    code = f"import importlib; print('\\n'.join(importlib.import_module(p).__file__ for p in {PACKAGES!r}))"
    out = _run([str(installed / "python"), "-c", code], cwd=tmp_path, timeout=120)
    assert out.returncode == 0, out.stderr
    files = out.stdout.split()
    assert len(files) == len(PACKAGES)
    venv = installed.parent.resolve()
    assert all(Path(f).resolve().is_relative_to(venv) for f in files), files


def test_mission_check_of_a_bundled_mission_outside_the_checkout(installed: Path, tmp_path: Path) -> None:
    out = _run([str(installed / "taskflight"), "mission", "check", "scan_and_search.yaml"], cwd=tmp_path,
               timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "ACCEPTED" in out.stdout
    assert str(installed.parent) in out.stderr  # the bundled file that was checked is named


def test_demo_flies_from_the_wheel(installed: Path, tmp_path: Path) -> None:
    out = _run([str(installed / "taskflight"), "demo", "--speedup", "10", "--sensors", "indoor"],
               cwd=tmp_path, timeout=400)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    assert "result: OK" in out.stdout
