"""Autopilot model: mavlink."""
