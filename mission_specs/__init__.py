"""The bundled mission files, behavior catalog, platforms, scenarios and team tasks, as package data.

Library code finds them through :func:`bundled` (``importlib.resources``), so an installed wheel has its
defaults as a source checkout does; users give their own files by path.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def bundled(name: str) -> Path:
    """The path of the bundled file ``name`` (e.g. ``"behavior_catalog.yaml"``).

    The package is installed as plain files (a wheel unpacked into site-packages, or this checkout),
    so the resource is a real file; :class:`FileNotFoundError` names it when it is not there.
    """
    path = Path(str(files(__name__).joinpath(name)))
    if not path.is_file():
        raise FileNotFoundError(f"no bundled file {name!r} in {path.parent}")
    return path
