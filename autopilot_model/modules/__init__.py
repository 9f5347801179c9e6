"""Autopilot model: modules."""
