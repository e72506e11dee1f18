"""The online estimator's decisions as pure functions beside their thresholds.

``quality``: what the estimate's quality says; ``input_gate``: which input samples are glitches. Each takes a small
read-only view and returns a verdict; the stateful classes (``online/estimator.py``, ``online/startup.py``,
``online/recovery.py``, ``online/inputs.py``) gather the view and act on the verdict.
"""
