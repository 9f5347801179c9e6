"""Taskflight: shared utilities (configuration files, clocks) and the ``taskflight`` command line."""

__version__ = "0.1.0"
