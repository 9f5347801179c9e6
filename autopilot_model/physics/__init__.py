"""Autopilot model: physics."""
