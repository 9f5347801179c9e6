"""Taskflight's bottom package: utilities every layer may import (clocks, configuration errors with
file:line:field, ArduPilot-compatible geodesy, loopback ports, tokens, process runtime, JSON lines).

It imports nothing else of the project: the autopilot model, the companion, the ground service and the
command line all stand on it (``docs/architecture.md``).
"""
