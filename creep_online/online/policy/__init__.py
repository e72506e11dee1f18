"""Decisions of the online trackers as small pure functions beside their thresholds (no state, no kernels)."""
