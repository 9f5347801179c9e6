"""The bundled software-in-the-loop autopilot model: an ArduCopter stand-in (seed 002 architecture)."""
