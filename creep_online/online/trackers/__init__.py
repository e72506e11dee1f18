"""The trackers that follow the plant after the start-up search, behind one declared interface (``Tracker``)."""
from .protocol import Tracker

__all__ = ["Tracker"]
