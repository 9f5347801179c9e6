"""Taskflight's top package: the ``taskflight`` command line and its launchers (``up``, the demos,
``fig16``, ``mission check``, team tasking). Nothing in the project imports it; the shared utilities
live in :mod:`taskflight_common`.
"""

__version__ = "0.1.0"
