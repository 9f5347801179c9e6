"""The differential scenarios: one ground station's script flown on the bundled model and on ArduPilot's
copter SITL, returning what the station saw, so the tests compare the two (docs/conformance.md)."""
