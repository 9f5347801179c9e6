"""The companion: one process per vehicle between the task layers and the autopilot.

Seed 000 Sec. IV-V: flight commands executed by a command queue with the QAPI verbs
(:mod:`companion.flight`), streamed as MAVLink setpoints to an ArduCopter-compatible autopilot
(:mod:`companion.link`), tied together by the QuadNode of Fig. 10 (:mod:`companion.node`), with a
local HTTP control surface (:mod:`companion.http`) and the ``taskflight companion`` command
(:mod:`companion.main`).
"""
