"""The trackers that follow the plant after the start-up search, behind one declared interface (``Tracker``):
``WindowTracker`` (re-fits over an exponentially forgotten window) and ``RecursiveTracker`` (a recursive
prediction-error method), with their ``TrackerSettings``."""
from .protocol import Tracker
from .recursive import RecursiveTracker
from .settings import TrackerSettings
from .window import WindowTracker

__all__ = ["Tracker", "WindowTracker", "RecursiveTracker", "TrackerSettings"]
