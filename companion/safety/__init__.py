"""The companion's safety monitor (the emergency requester): :mod:`.monitor`, :mod:`.config`."""

from .config import Action, SafetyConfig, load_safety_config
from .monitor import SafetyDecision, SafetyMonitor

__all__ = ["Action", "SafetyConfig", "SafetyDecision", "SafetyMonitor", "load_safety_config"]
