"""Taskflight ground station: the operator's FastAPI service and web UI (team tasking, pause / break-in
with a joystick, resume, enough, user confirmation). It drives each vehicle's companion through the
companion's local control surface (:mod:`companion.http`); see ``../shared/ARCHITECTURE.md``.

Not built yet: this package is the place for it (a later issue).
"""
