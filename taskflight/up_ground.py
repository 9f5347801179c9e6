"""The ground service's part of ``taskflight up``: the tokens file, its arguments, the fence and map tiles
it is given (:mod:`taskflight.up` starts it)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from taskflight_common.geo import ned_to_geodetic

if TYPE_CHECKING:
    from taskflight.up import VehicleInfo


def write_tokens(path: Path, tokens: dict[str, list[str]]) -> None:
    """Write the tokens file readable by its owner only (mode 0600 from its creation on)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        yaml.safe_dump(tokens, f)
    os.chmod(tmp, 0o600)
    os.replace(tmp, path)


def ground_available() -> bool:
    """Whether ``taskflight ground`` (the ground service) is part of this installation."""
    import importlib.util

    try:
        return importlib.util.find_spec("groundstation.service") is not None
    except (ImportError, ValueError):
        return False


def write_fence(platform: Path, path: Path) -> Path | None:
    """The platform's envelope (north/east metres around its home) as a ``fence: [[lat, lon], ...]`` file
    for the ground service, which refuses tasks outside it and draws it; None without a horizontal one."""
    from companion.tst.platform import load_platform

    p = load_platform(platform)
    if p.envelope.vertices is None:
        return None
    origin = (p.home[0], p.home[1], 0.0)
    points = [list(ned_to_geodetic(origin, n, e, 0.0)[:2]) for n, e in p.envelope.vertices]
    path.write_text(f"fence: {points}\n")
    return path


def demo_tiles(platform: Path, path: Path) -> Path:
    """The offline map tiles around the platform's home (:mod:`taskflight.demo_tiles`; drawn once, kept in the
    state folder)."""
    from companion.tst.platform import load_platform
    from taskflight.demo_tiles import ensure_mbtiles

    return ensure_mbtiles(path, load_platform(platform).home)


def ground_arguments(team_url: str, db: Path, host: str, port: int, tokens: Path,
                     vehicles: list[VehicleInfo], resume_tasks: bool = False) -> list[str]:
    """``taskflight ground ...``'s arguments for this fleet (each vehicle's companion by system id). The
    companion token is not among them (``ps`` shows every argument to every user): the ground service
    takes it from its environment (:data:`~taskflight_common.tokens.TOKEN_ENV`)."""
    argv = ["ground", "--team", team_url, "--db", str(db), "--host", host, "--port", str(port),
            "--tokens", str(tokens)]
    for v in vehicles:
        argv += ["--companion", f"{v.sysid}={v.control_url}"]
    return [*argv, "--resume-tasks"] if resume_tasks else argv
