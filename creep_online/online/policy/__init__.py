"""The online estimator's decisions as pure functions beside their thresholds (no state, no kernels).

``quality``: what the estimate's quality says; ``input_gate``: which input samples are glitches; ``change``: when the
plant has changed (the window tracker's likelihood-ratio test, the recursive tracker's GLR); ``research``: when the
window tracker searches for the resonance again. Each takes a small read-only view and returns a verdict; the
stateful classes (``online/estimator.py``, ``online/startup.py``, ``online/recovery.py``, ``online/inputs.py``,
``online/trackers/``) gather the view and act on the verdict.
"""
