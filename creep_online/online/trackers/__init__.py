"""The online trackers: ``WindowTracker`` (re-fits over an exponentially forgotten window) and
``RecursiveTracker`` (a recursive prediction-error method), with their ``TrackerSettings``."""
from .recursive import RecursiveTracker
from .settings import TrackerSettings
from .window import WindowTracker

__all__ = ["WindowTracker", "RecursiveTracker", "TrackerSettings"]
