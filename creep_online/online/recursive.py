"""The recursive tracker's import path: ``creep_online.online.trackers.recursive`` (re-exported here)."""
from .trackers.recursive import RecursiveTracker, warm

__all__ = ["RecursiveTracker", "warm"]
