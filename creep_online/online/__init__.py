"""Online identification of the fractional creep model (docs/online.md).

``OnlineEstimator.update(u, y)`` takes one sample at a time (bounded work),
``update_block`` many; ``estimate`` is the current ``OnlineEstimate``. See
docs/online.md for the scheme, the defaults and the measurements behind them.
``CreepCompensator`` turns a reference into the command that makes the plant
follow it, from the (live) model (docs/compensation.md); ``ModelGate`` says which
model it may take from each live estimate. ``OnlineSettings`` holds the estimator's thresholds (``settings=``).
"""
from .compensator import CreepCompensator
from .estimator import OnlineEstimate, OnlineEstimator, warm_kernels
from .gate import ModelGate
from .settings import OnlineSettings

__all__ = ["OnlineEstimator", "OnlineEstimate", "warm_kernels", "CreepCompensator", "ModelGate", "OnlineSettings"]
