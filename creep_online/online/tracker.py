"""The window tracker's import path: ``creep_online.online.trackers.window`` (re-exported here)."""
from .trackers.settings import TrackerSettings
from .trackers.window import Fit, WindowTracker

__all__ = ["WindowTracker", "Fit", "TrackerSettings"]
